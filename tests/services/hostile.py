"""A hostile model bundle (issue 14): a 1.5 KB skillset whose guards expand exponentially.

Ten resources of four states and ten skills whose precondition is ``a!=x and
b!=x and ...``: each ``!=`` expands to three states (SPEC §3, DNF), so each
precondition has 3^10 = 59 049 clauses and the net about 590 000 transitions,
gigabytes to build, before any exploration.  Consistent (its digest is right), so
a predictor can only bound what it costs, not refuse it.
"""

from __future__ import annotations

import zenoh

from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.convert import bundle_digest
from skinet.wire.messages import ModelBundle, PredictRequest

SYSTEM = "h"


def hostile_rl(resources: int = 10, skills: int = 10, states: int = 4) -> str:
    names = "abcdefghijklmnopqrstuvwxyz"[:resources]
    kinds = " ".join("xyzwvu"[:states])
    res = " ".join(f"{n}{{state{{{kinds}}}initial x}}" for n in names)
    guard = " and ".join(f"{n}!=x" for n in names)
    body = " ".join(f"skill k{i}{{precondition{{p:{guard}}}}}"
                    for i in range(skills))
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
        return list(self.session.get(keys.predict(SYSTEM), payload=self.request(budget, seq), timeout=timeout))

    def close(self) -> None:
        self._queryable.undeclare()
