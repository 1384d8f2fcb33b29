"""From manager messages (CDR) to canonical events, shared by live and replay (SPEC §1).

:class:`Feed` decodes each message with the skillset's type store, hands it to the
skillset's :class:`~skinet.ros.derive.Deriver` and numbers the resulting
:class:`~skinet.wire.messages.CanonicalEvent` per skillset (0, 1, 2, ...).  A
payload that does not decode is logged and dropped (SPEC §7).  A status that
overtook one of its responses waits for it (bounded).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from skinet.ros import derive
from skinet.ros.keys import ManagerTopic, manager_topics, topic_fqn
from skinet.ros.typestore import Typestore, build_typestore, decode, to_plain
from skinet.system import Component, System
from skinet.wire.messages import CanonicalEvent

log = logging.getLogger("skinet.bridge_ros2")

WATCHED = ("status", "event_request", "event_response", "skill_response")


@dataclass
class Counters:
    messages: int = 0  # manager messages fed
    malformed: int = 0  # payloads that did not decode
    events: int = 0  # canonical events produced
    unexplained: int = 0  # canonical events without a transition name


@dataclass
class _Held:
    """A status waiting for the responses it overtook."""

    status: derive.Status
    since: float  # clock time it arrived
    awaits: str  # what it waits for (for the log)


@dataclass
class _Manager:
    component: Component
    store: Typestore
    deriver: derive.Deriver
    topics: list[ManagerTopic]  # the watched ones
    seq: int = 0
    held: _Held | None = None


class Feed:
    """Derivation state of every skillset of ``system`` (not thread-safe).

    A status that overtook a response it needs (:meth:`Deriver.awaits`) is held
    until that response comes, a newer status comes, or ``hold`` seconds of
    ``clock`` pass (:meth:`expire`, called by the bridge when :meth:`deadline` is
    due); a status that needs nothing is derived at once.
    """

    def __init__(self, system: System, typemap: Mapping[str, str], source: str,
                 extra_types: Mapping[str, str] | None = None, *, hold: float = 0.5,
                 clock: Callable[[], float] = time.monotonic):
        self.system = system
        self.source = source
        self.hold = hold
        self.clock = clock
        self.counters = Counters()
        self.statuses: dict[str, int] = {c.name: 0 for c in system.components}  # statuses derived per skillset
        self.managers: dict[str, _Manager] = {}
        for c in system.components:
            store = build_typestore(c.skillset, typemap, extra_types)
            topics = [t for t in manager_topics(c.skillset) if t.kind in WATCHED]
            self.managers[c.name] = _Manager(c, store, derive.Deriver(c.skillset, c.net), topics)

    def by_fqn(self) -> dict[str, tuple[str, ManagerTopic]]:
        """ROS topic name (``/spot/spot_skillset_manager/spot_skillset/status``) -> (skillset, topic)."""
        return {topic_fqn(m.component.manager, t.topic): (name, t)
                for name, m in self.managers.items() for t in m.topics}

    def feed(self, skillset: str, topic: ManagerTopic, payload: bytes) -> list[CanonicalEvent]:
        """Canonical events caused by one CDR message of ``skillset``'s manager."""
        m = self.managers[skillset]
        self.counters.messages += 1
        ss = m.component.skillset
        try:
            msg = to_plain(decode(m.store, topic.typename, payload))
            if topic.kind == "status":
                status = derive.status_from_plain(ss, msg)
            elif topic.kind == "skill_response":
                out = m.deriver.on_skill_response(derive.skill_response_from_plain(ss, topic.skill or "", msg))
            elif topic.kind == "event_response":
                out = m.deriver.on_event_response(derive.event_response_from_plain(msg))
            else:
                out = m.deriver.on_event_request(derive.event_request_from_plain(msg))
        except Exception as exc:  # rosbags raises several types on bad CDR; views raise KeyError
            self.counters.malformed += 1
            log.warning("%s: malformed %s dropped: %s", skillset, topic.topic, exc)
            return []
        if topic.kind != "status":
            events = self._emit(m, out)
            if m.held is not None and m.deriver.awaits(m.held.status) is None:
                events += self._release(m)
            return events
        events = self._release(m) if m.held is not None else []  # a newer status: the held one goes first
        awaits = m.deriver.awaits(status)
        if awaits is not None and self.hold > 0:
            m.held = _Held(status, self.clock(), awaits)
            return events
        return events + self._status(m, status)

    def deadline(self) -> float | None:
        """Clock time when the first held status must be released (``None``: none held)."""
        return min((m.held.since + self.hold for m in self.managers.values() if m.held), default=None)

    def expire(self, now: float | None = None) -> list[CanonicalEvent]:
        """Derive the statuses held for ``hold`` seconds or more, without what they wait for."""
        now = self.clock() if now is None else now
        events: list[CanonicalEvent] = []
        for name, m in self.managers.items():
            if m.held is not None and now >= m.held.since + self.hold:
                log.warning("%s: status derived without %s (not received within %.2f s)", name, m.held.awaits,
                            self.hold)
                events += self._release(m)
        return events

    def flush(self) -> list[CanonicalEvent]:
        """Derive every held status now (end of a replay)."""
        return [ev for m in self.managers.values() if m.held is not None for ev in self._release(m)]

    def _release(self, m: _Manager) -> list[CanonicalEvent]:
        assert m.held is not None
        status, m.held = m.held.status, None
        return self._status(m, status)

    def _status(self, m: _Manager, status: derive.Status) -> list[CanonicalEvent]:
        self.statuses[m.component.name] += 1
        return self._emit(m, m.deriver.on_status(status))

    def _emit(self, m: _Manager, out: derive.Output) -> list[CanonicalEvent]:
        for note in out.notes:
            log.info("%s", note)
        events = []
        for d in out.events:
            events.append(CanonicalEvent(system=self.system.name, skillset=m.component.name, seq=m.seq,
                                         stamp=d.stamp, source=self.source, transition=d.transition,
                                         status=d.status, info=d.info))
            m.seq += 1
            self.counters.unexplained += d.transition is None
        self.counters.events += len(events)
        return events

    def has_status(self, skillset: str) -> bool:
        """Whether a status of ``skillset`` was received."""
        m = self.managers[skillset]
        return m.deriver.last is not None or m.held is not None


__all__ = ["Counters", "Feed"]
