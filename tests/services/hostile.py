"""A hostile model bundle (issue 14): a 1.9 KB skillset whose nets are costly to build.

Ten resources of three states and ten skills whose precondition is ``a!=z and
b!=z and ...``: each ``!=`` expands to two states (docs/semantics.md §3, DNF), so each
precondition has 2^10 = 1024 clauses, the most the parser accepts, and the net
about 10 000 transitions, seconds to build before any exploration; with more
skills (``skills=80``) it takes gigabytes.  Consistent (its digest is right), so a
predictor can only bound what it costs, not refuse it.
"""

from __future__ import annotations

import zenoh

from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.convert import bundle_digest
from skinet.wire.messages import ModelBundle, PredictRequest

SYSTEM = "h"


def hostile_rl(resources: int = 10, skills: int = 10, states: int = 3) -> str:
    names = "abcdefghijklmnopqrstuvwxyz"[:resources]
    kinds = " ".join("xyzwvu"[:states])
    res = " ".join(f"{n}{{state{{{kinds}}}initial x}}" for n in names)
    guard = " and ".join(f"{n}!={kinds[-1]}" for n in names)
    body = " ".join(f"skill k{i}{{precondition{{p:{guard}}}start{{{names[i % resources]}->y}}"
                    f"success s{{effect {names[i % resources]}->x}}}}" for i in range(skills))
    return f"skillset h{{resource{{{res}}}{body}}}"


def hostile_bundle(**shape: int) -> ModelBundle:
    b = ModelBundle(system=SYSTEM, digest="", skillsets=[("h.rl", hostile_rl(**shape), "/h/h_skillset_manager")],
                    properties="", properties_name="h.props")
    return b.model_copy(update={"digest": bundle_digest(b)})


class Attacker:
    """Any peer: serves the hostile bundle on its model key and asks for predictions of it."""

    def __init__(self, session: zenoh.Session, b: ModelBundle | None = None):
        self.session, self.bundle = session, b or hostile_bundle()
        self._payload = encode(self.bundle)
        self._queryable = session.declare_queryable(keys.model(SYSTEM, self.bundle.digest), self._serve)

    def _serve(self, query: zenoh.Query) -> None:
        with query:
            query.reply(str(query.key_expr), self._payload)

    def request(self, budget: float = 0.1, seq: int = 1) -> bytes:
        return encode(PredictRequest(system=SYSTEM, digest=self.bundle.digest, seq=seq, skillsets={}, budget=budget))

    def ask(self, budget: float = 0.1, seq: int = 1, timeout: float = 30.0) -> list[zenoh.Reply]:
        return list(self.session.get(keys.predict(SYSTEM, keys.LOCAL_CLIENT), payload=self.request(budget, seq), timeout=timeout))

    def close(self) -> None:
        self._queryable.undeclare()
