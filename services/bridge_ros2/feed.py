"""From manager messages (CDR) to canonical events, shared by live and replay (docs/semantics.md §1).

:class:`Feed` decodes each message with the skillset's type store, hands it to the
skillset's :class:`~skinet.ros.derive.Deriver` and numbers the resulting
:class:`~skinet.wire.messages.CanonicalEvent` per skillset (0, 1, 2, ...) within
an epoch, the feed's start time in milliseconds, so that a monitor recognises a
restarted bridge (issue 14).  A payload that does not decode is logged and dropped
(docs/semantics.md §7).  A status that overtook one of its responses waits for it (bounded), and
the events of other skillsets that arrive meanwhile wait behind it: the bridge emits
events in the order their messages arrived, across skillsets too (and across the
bound skillsets of the same bridge process, which share its
:class:`~services.bridge_ros2.order.Order`), so that the monitor follows the
interleaving the robot went through.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from services.bridge_ros2.order import Order, Slot
from skinet.ros import derive
from skinet.ros.interfaces import status_field
from skinet.ros.keys import ManagerTopic, manager_topics, parse_rmw_attachment, topic_fqn
from skinet.ros.typestore import build_typestore, decode, to_plain
from skinet.system.model import Component, System
from skinet.wire.messages import CanonicalEvent, MissedOutcome, SkillsetStatus

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

log = logging.getLogger("skinet.bridge_ros2")

WATCHED = ("status", "event_request", "event_response", "skill_response")


@dataclass
class Counters:
    messages: int = 0  # manager messages fed
    malformed: int = 0  # payloads that did not decode
    events: int = 0  # canonical events produced
    unexplained: int = 0  # canonical events without a transition name
    restarts: int = 0  # managers that came back (new process, or their gateway reconnected)
    resyncs: int = 0  # statuses asked again after the link to the managers was cut (their messages lost)
    mismatched: int = 0  # statuses naming skills or resources the model lacks


@dataclass
class _Held:
    """A status waiting for the responses it overtook."""

    status: derive.Status
    since: float  # clock time it arrived
    awaits: str  # what it waits for (for the log)
    slot: Slot  # its place in the order (it takes its skillset's events from responses)


@dataclass
class _Manager:
    component: Component
    store: Typestore
    deriver: derive.Deriver
    topics: list[ManagerTopic]  # the watched ones
    seq: int = 0
    held: _Held | None = None
    restart: str = ""  # why the next status starts afresh (the manager restarted)
    resync: str = ""  # why the next status follows a gap: the manager's messages since its last one are lost
    publisher: tuple[bytes, int] | None = None  # rmw_zenoh: GID and sequence number of the last status
    reported: set[str] = field(default_factory=set)  # kinds of bad input already logged


class Feed:
    """Derivation state of every skillset of ``system`` (not thread-safe).

    A status that overtook a response it needs (:meth:`Deriver.awaits`) is held
    until that response comes, a newer status comes, or ``hold`` seconds of
    ``clock`` pass (:meth:`expire`, called by the bridge when :meth:`deadline` is
    due); a status that needs nothing is derived at once.  Events come out in the
    order their messages came in: those of other skillsets that follow a held status
    wait with it (at most ``hold`` seconds), while the held skillset's own events from
    responses go before it, as the messages they come from were sent before it.
    """

    def __init__(self, system: System, typemap: Mapping[str, str], source: str,
                 extra_types: Mapping[str, str] | None = None, *, hold: float = 0.5,
                 clock: Callable[[], float] = time.monotonic, epoch: int | None = None, order: Order | None = None):
        self.system = system
        self.source = source
        self.hold = hold
        self.clock = clock
        self.epoch = time.time_ns() // 1_000_000 if epoch is None else epoch
        self.counters = Counters()
        self.statuses: dict[str, int] = {c.name: 0 for c in system.components if not c.binding}  # statuses derived
        self.managers: dict[str, _Manager] = {}
        self.order = Order() if order is None else order  # shared with the bound skillsets' feed, if any
        for c in system.components:
            if c.binding:  # bound to plain ROS 2 interfaces: services.bridge_ros2.bound
                continue
            store = build_typestore(c.skillset, typemap, extra_types)
            topics = [t for t in manager_topics(c.skillset) if t.kind in WATCHED]
            self.managers[c.name] = _Manager(c, store, derive.Deriver(c.skillset, c.net), topics)

    def by_fqn(self) -> dict[str, tuple[str, ManagerTopic]]:
        """ROS topic name (``/spot/spot_skillset_manager/spot_skillset/status``) -> (skillset, topic)."""
        return {topic_fqn(m.component.manager, t.topic): (name, t)
                for name, m in self.managers.items() for t in m.topics}

    def feed(self, skillset: str, topic: ManagerTopic, payload: bytes,
             attachment: bytes | None = None) -> list[CanonicalEvent]:
        """Canonical events caused by one CDR message of ``skillset``'s manager.

        ``attachment``: the ``rmw_zenoh`` attachment of the sample, if any; a status
        from a new publisher GID, or with a sequence number going back, comes from a
        restarted manager.
        """
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
            self._report(m, f"malformed {topic.topic} dropped ({type(exc).__name__}: {exc})",
                         f"malformed {topic.topic} {type(exc).__name__}")
            return self._drain()
        if topic.kind != "status":
            self._place(m, self._emit(m, out))
            if m.held is not None and m.deriver.awaits(m.held.status) is None:
                self._release(m)
            return self._drain()
        self._check_model(m, msg)
        self._check_publisher(m, attachment)
        self._check_ids(m, status)
        if m.held is not None:  # a newer status: the held one goes first
            self._release(m)
        # A new initial status needs nothing; after a gap, what it awaits was lost.
        awaits = None if m.restart or m.resync else m.deriver.awaits(status)
        if awaits is not None and self.hold > 0:
            m.held = _Held(status, self.clock(), awaits, self.order.open())
        else:
            self._place(m, self._status(m, status))
        return self._drain()

    def deadline(self) -> float | None:
        """Clock time when :meth:`expire` is due: a held status must be released, or events
        released outside :meth:`feed` wait to be taken (``None``: nothing to do)."""
        if self.order.due():
            return self.clock()
        return min((m.held.since + self.hold for m in self.managers.values() if m.held), default=None)

    def expire(self, now: float | None = None) -> list[CanonicalEvent]:
        """Derive the statuses held for ``hold`` seconds or more, without what they wait for;
        returns the events now in order (also those :meth:`restarted` released)."""
        now = self.clock() if now is None else now
        for name, m in self.managers.items():
            if m.held is not None and now >= m.held.since + self.hold:
                log.warning("%s: status derived without %s (not received within %.2f s)", name, m.held.awaits,
                            self.hold)
                self._release(m, f"the response did not come within {self.hold:g} s")
        return self._drain()

    def flush(self) -> list[CanonicalEvent]:
        """Derive every held status now (end of a replay)."""
        for m in self.managers.values():
            if m.held is not None:
                self._release(m)
        return self._drain()

    def _place(self, m: _Manager, events: list[CanonicalEvent]) -> None:
        """Events of ``m`` that are not its held status: before that status, else after everything."""
        if m.held is not None:
            m.held.slot.events += events
        else:
            self.order.place(events)

    def _release(self, m: _Manager, gap: str = "") -> None:
        """Derive ``m``'s held status in its place; ``gap``: why a response it waited for may be missing."""
        assert m.held is not None
        held, m.held = m.held, None
        self.order.close(held.slot, self._status(m, held.status, gap))

    def _drain(self) -> list[CanonicalEvent]:
        """The events whose turn has come: up to the first held status (or bound skillset waiting)."""
        return self.order.drain()

    def restarted(self, skillset: str, why: str) -> None:
        """``skillset``'s manager restarted: its next status is a new initial status (docs/semantics.md §7).

        A status still held from before is derived in its place (the next :meth:`feed`
        or :meth:`expire` returns its events).  The monitor then follows the new status,
        and reports a divergence when no transition of the model leads to it.
        """
        m = self.managers[skillset]
        if m.held is not None:
            self._release(m)
        if not m.restart:
            self.counters.restarts += 1
            log.warning("%s: manager %s restarted (%s); its next status starts afresh", skillset,
                        m.component.manager, why)
        m.restart = why
        m.publisher = None

    def resync(self, skillset: str, why: str) -> None:
        """Messages of ``skillset``'s manager may have been lost (the link was cut): its next
        status closes the gap, and its event says so (docs/semantics.md §7: never lost without a trace).

        Unlike :meth:`restarted`, the manager kept its state and execution ids: the next
        status is derived from the last one as usual.  Counted once per gap.
        """
        m = self.managers[skillset]
        if m.deriver.last is None and m.held is None:
            return  # nothing known yet: the first status is the initial one anyway
        if m.held is not None:
            self._release(m)
        if not m.resync:
            self.counters.resyncs += 1
            log.warning("%s: messages of manager %s may be lost (%s); its next status closes the gap", skillset,
                        m.component.manager, why)
        m.resync = why

    def _check_publisher(self, m: _Manager, attachment: bytes | None) -> None:
        if attachment is None:
            return
        try:
            sequence, _, gid = parse_rmw_attachment(attachment)
        except ValueError:
            return
        if m.publisher is not None and m.deriver.last is not None and \
                (gid != m.publisher[0] or sequence <= m.publisher[1]):
            why = "new status publisher" if gid != m.publisher[0] else "status sequence number went back"
            self.restarted(m.component.name, why)
        m.publisher = (gid, sequence)

    def _check_model(self, m: _Manager, msg: Mapping) -> None:
        """Count a status naming resources, states or skills the model lacks; report each kind once."""
        ss = m.component.skillset
        states = {r.name: r.states for r in ss.resources}
        problems = []
        for r in msg.get("resources", []):
            name, state = str(r.get("name", "")), str(r.get("state", ""))
            if name not in states:
                problems.append(f"resource '{name}' is not in the model")
            elif state not in states[name]:
                problems.append(f"resource '{name}' in state '{state}', not one of the model's")
        for k in ss.skills:
            named = str(msg.get(status_field(k), {}).get("name", ""))
            if named and named != k.name:
                problems.append(f"field {status_field(k)} names skill '{named}', not '{k.name}'")
        if problems:
            self.counters.mismatched += 1
        for problem in problems:
            self._report(m, f"status does not match the model: {problem}", problem)

    def _report(self, m: _Manager, message: str, kind: str) -> None:
        """Log ``message`` the first time a problem of ``kind`` shows up for this manager."""
        if kind not in m.reported:
            m.reported.add(kind)
            log.warning("%s: %s (reported once; see the bridge's counters)", m.component.name, message)

    def _check_ids(self, m: _Manager, status: derive.Status) -> None:
        """A manager never forgets an execution id: ids back to '' mean it restarted."""
        last = m.held.status if m.held is not None else m.deriver.last
        if last is None or m.restart:
            return
        reset = [k for k, v in status.skills.items() if v.id == "" and last.skills[k].id != ""]
        if reset:
            self.restarted(m.component.name, f"skill ids reset: {', '.join(reset)}")

    def _status(self, m: _Manager, status: derive.Status, gap: str = "") -> list[CanonicalEvent]:
        """Events of one status; ``gap``: what a skill found ended without its response is put down to
        (a resync's or a restart's reason comes first)."""
        self.statuses[m.component.name] += 1
        if m.resync and not m.restart:
            gap = m.resync
            return self._emit(m, self._resynced(m, status), gap=gap)
        m.resync = ""  # a restart is the stronger news
        if not m.restart:
            return self._emit(m, m.deriver.on_status(status), gap=gap or "the response was not received")
        last, m.deriver = m.deriver.last, derive.Deriver(m.component.skillset, m.component.net)
        out = m.deriver.on_status(status)
        if last is not None and out.events:  # skills it ran before are over (a new process runs none of them)
            ended = tuple(k for k, v in last.skills.items() if v.state != derive.READY and
                          (status.skills[k].state == derive.READY or status.skills[k].id != v.id))
            out.events[-1] = replace(out.events[-1], missed=ended)
            gap = f"manager {m.component.manager} restarted ({m.restart})"
        diverged = differences(last.wire(), status.wire()) if last is not None else "nothing known before"
        info = f"manager restarted ({m.restart}); state now differs: {diverged}" if diverged else \
            f"manager restarted ({m.restart}); same state as before"
        log.warning("%s: %s", m.component.name, info)
        out.events = [replace(d, info=info) for d in out.events]
        m.restart = ""
        return self._emit(m, out, restart=True, gap=gap)

    def _resynced(self, m: _Manager, status: derive.Status) -> derive.Output:
        """The status after a gap, derived from the last one; every event says so, and an
        unchanged status is published too, so the gap always leaves a trace."""
        last = m.deriver.last
        out = m.deriver.on_status(status)
        diverged = differences(last.wire(), status.wire()) if last is not None else ""
        info = f"resync after {m.resync}; " + (f"state now differs: {diverged}" if diverged else "same state as before")
        log.warning("%s: %s", m.component.name, info)
        m.resync = ""
        if not out.events:
            out.events.append(derive.Derived(None, status.wire(), status.stamp, info))
        else:
            out.events = [replace(d, info="; ".join(x for x in (info, d.info) if x)) for d in out.events]
        return out

    def _emit(self, m: _Manager, out: derive.Output, restart: bool = False, gap: str = "") -> list[CanonicalEvent]:
        """``out``'s events numbered and stamped for the wire; ``restart``: they follow a restart of the manager;
        ``gap``: why the skills an event names as ended without their response missed it (its ``missed``)."""
        for note in out.notes:
            log.info("%s", note)
        events = []
        for d in out.events:
            events.append(CanonicalEvent(system=self.system.name, skillset=m.component.name, seq=m.seq,
                                         stamp=d.stamp, source=self.source, epoch=self.epoch,
                                         transition=d.transition,
                                         status=d.status, info=d.info, restart=restart,
                                         missed=[MissedOutcome(skillset=m.component.name, skill=k, gap=gap)
                                                 for k in d.missed]))
            for k in d.missed:
                log.warning("%s: missed outcome of %s (%s)", m.component.name, k, gap)
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

    def outdated(self, skillset: str) -> str:
        """Why ``skillset``'s last status is known not to be its manager's current one ('' when it is not
        known to be): a restart or a cut link whose next status has not come yet (docs/semantics.md §7: nobody may
        vouch for it meanwhile)."""
        m = self.managers[skillset]
        if m.restart:
            return f"its manager restarted ({m.restart}): waiting for its new status"
        if m.resync:
            return f"{m.resync}: waiting for the status that closes the gap"
        return ""

    def has_status(self, skillset: str) -> bool:
        """Whether a status of ``skillset`` was received (since its manager restarted or the link
        to it was cut, if either happened)."""
        m = self.managers[skillset]
        return (m.deriver.last is not None or m.held is not None) and not m.restart and not m.resync


def differences(before: SkillsetStatus, now: SkillsetStatus) -> str:
    """What changed between two statuses, for a divergence or resync report: resources, then running skills."""
    out = [f"{r} {before.resources.get(r, '?')} -> {s}" for r, s in now.resources.items()
           if before.resources.get(r) != s]
    out += [f"{k} no longer running" for k in before.running if k not in now.running]
    out += [f"{k} running" for k in now.running if k not in before.running]
    return ", ".join(out)


__all__ = ["Counters", "Feed", "differences"]
