"""From manager messages (CDR) to canonical events, shared by live and replay (SPEC §1).

:class:`Feed` decodes each message with the skillset's type store, hands it to the
skillset's :class:`~skinet.ros.derive.Deriver` and numbers the resulting
:class:`~skinet.wire.messages.CanonicalEvent` per skillset (0, 1, 2, ...) within
an epoch, the feed's start time in milliseconds, so that a monitor recognises a
restarted bridge (issue 14).  A payload that does not decode is logged and dropped
(SPEC §7).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
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
class _Manager:
    component: Component
    store: Typestore
    deriver: derive.Deriver
    topics: list[ManagerTopic]  # the watched ones
    seq: int = 0


class Feed:
    """Derivation state of every skillset of ``system`` (not thread-safe)."""

    def __init__(self, system: System, typemap: Mapping[str, str], source: str,
                 extra_types: Mapping[str, str] | None = None, epoch: int | None = None):
        self.system = system
        self.source = source
        self.epoch = time.time_ns() // 1_000_000 if epoch is None else epoch
        self.counters = Counters()
        self.statuses: dict[str, int] = {c.name: 0 for c in system.components}  # statuses fed per skillset
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
        self.statuses[skillset] += topic.kind == "status"
        ss = m.component.skillset
        try:
            msg = to_plain(decode(m.store, topic.typename, payload))
            if topic.kind == "status":
                out = m.deriver.on_status(derive.status_from_plain(ss, msg))
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
        for note in out.notes:
            log.info("%s", note)
        events = []
        for d in out.events:
            events.append(CanonicalEvent(system=self.system.name, skillset=skillset, seq=m.seq, stamp=d.stamp,
                                         source=self.source, epoch=self.epoch, transition=d.transition,
                                         status=d.status, info=d.info))
            m.seq += 1
            self.counters.unexplained += d.transition is None
        self.counters.events += len(events)
        return events

    def last_status(self, skillset: str) -> CanonicalEvent | None:
        """A status-only event with ``skillset``'s last status, numbered as the last event
        produced (what a monitor resyncs from); None before the first status."""
        m = self.managers[skillset]
        last = m.deriver.last
        if last is None:
            return None
        return CanonicalEvent(system=self.system.name, skillset=skillset, seq=max(m.seq - 1, 0), stamp=last.stamp,
                              source=self.source, epoch=self.epoch, status=last.wire(), info="resync")

    def has_status(self, skillset: str) -> bool:
        """Whether a status of ``skillset`` was received."""
        return self.managers[skillset].deriver.last is not None


__all__ = ["Counters", "Feed"]
