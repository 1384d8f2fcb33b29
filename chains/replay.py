"""``skinet replay LOG``: a recorded run published again as its monitor published it (docs/semantics.md §7).

A monitor log (``skinet record``, ``skinet demo --log``: :mod:`skinet.wire.log`,
:mod:`skinet.wire.mcap_log`) holds what the monitor published on
``skinet/<system>/{state,verdicts,unsafe,state_space,divergences}``.  :class:`Replay`
publishes those messages again, unchanged (their stamps too), on the same keys
and at the recorded pace divided by ``speed``, so that ``skinet dashboard``,
``skinet watch`` and ``skinet record`` (then ``skinet timeline``) follow it as
they follow a live run.  Like the monitor it answers ``get`` on the five keys
with the last message published so far (late joiners), serves the log's model
bundle on ``skinet/<system>/model/<digest>`` and holds a liveliness token,
``skinet/<system>/alive/monitor/replay-<id>``, so that observers find it.

It is not a monitor and says so: the command check is answered with an error
(there is no live marking to judge a command on), the canonical events of the
log are not published (a running monitor would take them for the robot's), and
it refuses to start where a monitor of the same system is alive.  Cost: O(M) to
sort out a log of M messages, then O(1) per message.
"""

from __future__ import annotations

import math
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import zenoh

from services.common.zenoh_config import undeclare
from services.dashboard.observer import monitored_systems
from services.monitor.check import request_from
from skinet.errors import SkinetError, SourceError
from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.log import Entry
from skinet.wire.messages import CheckReply, ModelBundle

# The monitor's publications: message type -> its key.
RESULTS: dict[str, Callable[[str], str]] = {
    "LiveState": keys.state, "Verdicts": keys.verdicts, "UnsafeReport": keys.unsafe,
    "StateSpaceReport": keys.state_space, "Divergences": keys.divergences,
}
INSTANCE_PREFIX = "replay-"  # of the liveliness token's instance id: observers show who publishes


@dataclass(frozen=True)
class Recording:
    """What a replay of one log publishes."""

    system: str
    messages: tuple[Entry, ...]  # the monitor's publications, in recorded order
    model: ModelBundle | None  # the first model bundle of the log, if any
    left_out: dict[str, int]  # message type -> messages not published (canonical events, ...)

    @property
    def duration(self) -> float:
        """Seconds from the first publication to the last, as recorded."""
        return self.messages[-1].t - self.messages[0].t


def recording(entries: Sequence[Entry], source: str) -> Recording:
    """Sort out the monitor's publications of the log ``source``; :class:`SourceError` when it has
    none, or messages of several systems."""
    systems = sorted({getattr(e.message, "system", "") for e in entries} - {""})
    if len(systems) > 1:
        raise SourceError.at(source, None, f"the log holds messages of several systems ({', '.join(systems)}); "
                                           "a replay publishes one system's")
    messages = tuple(e for e in entries if e.type in RESULTS)
    if not messages:
        kinds = ", ".join(f"{n} {t}" for t, n in sorted(Counter(e.type for e in entries).items())) or "nothing"
        raise SourceError.at(source, None, f"no message of a monitor to replay ({', '.join(RESULTS)}): "
                                           f"the log holds {kinds}")
    model = next((e.message for e in entries if isinstance(e.message, ModelBundle)), None)
    left_out = Counter(e.type for e in entries if e.type not in RESULTS and e.type != "ModelBundle")
    return Recording(systems[0], messages, model, dict(sorted(left_out.items())))


class Replay:
    """Publishes a :class:`Recording` on ``session`` (which may be shared, e.g. with a dashboard)."""

    def __init__(self, session: zenoh.Session, rec: Recording, source: str, instance_id: str | None = None):
        self.session, self.recording, self.source = session, rec, source
        name = keys.check_chunk(rec.system, "system name")
        if name in monitored_systems(session):
            raise SkinetError(f"a monitor of system '{name}' is alive on this Zenoh network: a replay would mix "
                              "its messages with the live ones (stop that monitor, or replay on another network)")
        self.instance_id = keys.check_chunk(INSTANCE_PREFIX + (instance_id or uuid.uuid4().hex[:8]), "instance id")
        self.published = 0
        self._lock = threading.Lock()
        self._last: dict[str, bytes] = {}
        opts = dict(congestion_control=zenoh.CongestionControl.BLOCK)
        self._pubs = {kind: session.declare_publisher(key(name), **opts) for kind, key in RESULTS.items()}
        self._queryables = [session.declare_queryable(key(name), lambda q, k=kind: self._on_latest(k, q))
                            for kind, key in RESULTS.items()]
        self._queryables.append(session.declare_queryable(keys.check(name, "*"), self._on_check))
        if rec.model is not None:
            payload = encode(rec.model)
            model_key = keys.model(name, rec.model.digest)
            self._queryables.append(session.declare_queryable(model_key, lambda q: _reply(q, model_key, payload)))
        # Declared last: whoever sees the token also sees the declarations above.
        self._token = session.liveliness().declare_token(keys.alive(name, "monitor", self.instance_id))

    def play(self, speed: float = 1.0, stop: threading.Event | None = None,
             on_message: Callable[[Entry], None] | None = None) -> int:
        """Publish the messages at their recorded times divided by ``speed`` (<= 0 or ``inf``: as fast
        as possible) until the last one or ``stop``; returns how many were published."""
        stop = stop or threading.Event()
        paced = speed > 0 and not math.isinf(speed)
        origin, t0 = time.monotonic(), self.recording.messages[0].t
        for entry in self.recording.messages:
            if paced:
                stop.wait(max(0.0, origin + (entry.t - t0) / speed - time.monotonic()))
            if stop.is_set():
                break
            payload = encode(entry.message)
            with self._lock:
                self._pubs[entry.type].put(payload)
                self._last[entry.type] = payload
                self.published += 1
            if on_message is not None:
                on_message(entry)
        return self.published

    def close(self) -> None:
        undeclare(self._token, *self._queryables, *self._pubs.values())

    # -- queryables ---------------------------------------------------------------------

    def _on_latest(self, kind: str, query: zenoh.Query) -> None:
        with self._lock:
            payload = self._last.get(kind)
        with query:
            if payload is not None:
                query.reply(RESULTS[kind](self.recording.system), payload)

    def _on_check(self, query: zenoh.Query) -> None:
        name = self.recording.system
        with query:
            client = keys.client_of(str(query.key_expr)) or keys.LOCAL_CLIENT
            payload = query.payload.to_bytes() if query.payload is not None else None
            request = request_from(name, payload, str(query.parameters))
            asked = ("", "") if isinstance(request, CheckReply) else (request.skillset, request.transition)
            reply = CheckReply(system=name, skillset=asked[0], transition=asked[1], ok=False,
                               error=f"this is a replay of {self.source} (skinet replay), not the live robot: "
                                     "no command check")
            query.reply(keys.check(name, client), encode(reply))


def _reply(query: zenoh.Query, key: str, payload: bytes) -> None:
    with query:
        query.reply(key, payload)


__all__ = ["RESULTS", "Recording", "Replay", "recording"]
