"""A publisher of canonical events says it is alive: :class:`Heartbeat` every 0.5 s (docs/semantics.md §7, honest live state).

zenoh.ext's advanced publisher sends heartbeats of its own, but they are internal
to its subscriber (miss detection) and say nothing to the application.  This one
is for the monitor: it names the source and epoch of the events, the liveliness
token the publisher holds, and per skillset the seq of its last event and whether
its manager is present, and which skillsets' last status the publisher knows to
be outdated (``pending``, with why), on ``keys.heartbeat(system, source)``.  A
monitor that hears nothing from a source for its bound (2 s by default, four
periods) counts that source's skillsets as ``lost``; one told that a status is
pending stops vouching for it at once, so the publisher sends a heartbeat as soon
as that changes (:meth:`HeartbeatPublisher.poke`).  Cost: one small put per period
and per change.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import zenoh

from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.messages import Heartbeat, HeartbeatSkillset

log = logging.getLogger("skinet.heartbeat")

PERIOD = 0.5  # seconds between heartbeats


def refusal(source: str, skillset: str, why: str) -> str:
    """What a source says instead of a status it knows to be outdated: its error reply to a resync query,
    and the monitor's reason while the source's heartbeat lists the skillset as ``pending`` (same words)."""
    return f"'{source}' has no current status of {skillset}: {why}"


def silence(manager: str, requests: int, period: float) -> str:
    """Why a bridge lists a manager as gone that answered none of its last status requests (its heartbeat's
    ``pending``; the monitor's reason for the skillset then, as :func:`refusal` words it)."""
    return f"manager {manager} answered none of the last {requests} status requests ({period:g} s apart)"


def is_silence(why: str) -> bool:
    """Whether ``why`` (a heartbeat's ``pending`` reason) is a :func:`silence`."""
    return why.startswith("manager ") and " answered none of the last " in why


Beat = Callable[[], dict[str, HeartbeatSkillset]]
Pending = Callable[[], dict[str, str]]


class HeartbeatPublisher:
    """Publishes ``beat()`` (skillset -> :class:`HeartbeatSkillset`) and ``pending()`` (skillset -> why its
    last status is outdated) every ``period`` seconds from a thread, and at once on :meth:`poke`.  Several
    publishers of one source (the managers' and the bound skillsets' bridges of one process) share one
    heartbeat: each :meth:`add` its own skillsets."""

    def __init__(self, session: zenoh.Session, system: str, source: str, epoch: int, token: str,
                 beat: Beat, period: float = PERIOD, pending: Pending = dict):
        self.system, self.source, self.epoch, self.token, self.period = system, source, epoch, token, period
        self._parts: list[tuple[Beat, Pending]] = [(beat, pending)]
        self._poked = threading.Event()
        # DROP: a heartbeat stuck behind a dead link is worth nothing; the next one replaces it.
        self._pub = session.declare_publisher(keys.heartbeat(system, source), express=True)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="skinet-heartbeat", daemon=True)
        self._thread.start()

    def add(self, beat: Beat, pending: Pending = dict) -> None:
        """More skillsets of the same source and epoch in each heartbeat."""
        self._parts = [*self._parts, (beat, pending)]
        self.poke()

    def remove(self, beat: Beat) -> None:
        self._parts = [p for p in self._parts if p[0] != beat]  # bound methods: equal, not identical

    def message(self) -> Heartbeat:
        skillsets: dict[str, HeartbeatSkillset] = {}
        pending: dict[str, str] = {}
        for beat, outdated in self._parts:
            skillsets |= beat()
            pending |= outdated()
        return Heartbeat(system=self.system, source=self.source, epoch=self.epoch, period=self.period,
                         token=self.token, skillsets=skillsets, pending=pending)

    def poke(self) -> None:
        """Publish a heartbeat now (what it says changed), then go on every ``period`` seconds."""
        self._poked.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._poked.clear()
            try:
                self._pub.put(encode(self.message()))
            except zenoh.ZError:
                return  # the session closed under us
            except Exception:  # a bug must not stop the publisher's process
                log.exception("cannot publish a heartbeat")
            self._poked.wait(self.period)

    def close(self) -> None:
        self._stop.set()
        self._poked.set()
        self._thread.join(2.0)
        try:
            self._pub.undeclare()
        except zenoh.ZError:
            pass
