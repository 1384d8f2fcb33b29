"""From plain ROS 2 interfaces (CDR) to canonical events through bindings, shared by live and replay (docs/semantics.md §9).

:class:`BoundFeed` decodes each message of a bound topic with the binding's type
store, hands it to the skillset's :class:`~skinet.ros.bound.BoundDeriver` and numbers
the resulting :class:`~skinet.wire.messages.CanonicalEvent` per skillset within an
epoch, as :class:`~services.bridge_ros2.feed.Feed` does for managers.  Drifts are
logged with the message that showed them, counted and kept (``drifts``, for
``skinet conform``); bad input (a payload that does not decode, a goal never seen
accepted, a status code that is no GoalStatus, ...) is counted per kind and logged
once per kind; the feed never raises on a message.  Events leave in the order their
messages came (:class:`~services.bridge_ros2.order.Order`, shared with the managers'
feed of the same bridge): while a skillset waits for a goal's result, the events of
every other skillset that come later wait behind it (at most the result's timeout).

What the bridge can vouch for (docs/semantics.md §7, §9): until every bound interface of a
skillset has been read once, and again after the link to the robot was cut or an
action server or lifecycle node left (:meth:`BoundFeed.unread`: the robot's topics
are volatile, what happened meanwhile is lost), the skillset's status is *pending*
(:meth:`BoundFeed.pending` says why); the reading that completes a gap publishes a
status event saying so (``resync after ...; state now differs: ...``), as the
managers' feed does.

:func:`replay_bags` reads a rosbag2 file (sqlite3 or mcap) once and feeds every
manager topic to a :class:`~services.bridge_ros2.feed.Feed` and every bound topic
to a :class:`BoundFeed`, in time order.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from services.bridge_ros2.feed import Feed, differences
from services.bridge_ros2.order import Order, Slot
from skinet.errors import SourceError
from skinet.ros import bound
from skinet.ros.actions import get_result_reply, get_state_reply
from skinet.ros.binding import STATUS_TYPE, TRANSITION_EVENT_TYPE, Binding
from skinet.ros.derive import Derived
from skinet.ros.typestore import decode, to_plain
from skinet.system.model import System
from skinet.wire.messages import CanonicalEvent, SkillsetStatus

log = logging.getLogger("skinet.bridge_ros2")


@dataclass(frozen=True)
class Route:
    """What one bound topic feeds: ``kind`` is ``status`` (an action's), ``lifecycle`` or ``topic``."""

    skillset: str
    kind: str
    typename: str
    owner: str = ""  # the skill (status) or resource (lifecycle)
    reads: str = ""  # the interface a message of it reads (BoundFeed.interfaces), if any


@dataclass
class BoundCounters:
    messages: int = 0  # bound topic messages fed
    malformed: int = 0  # payloads that did not decode
    events: int = 0  # canonical events produced
    drifts: int = 0  # model divergences found (docs/semantics.md §9)
    resyncs: int = 0  # gaps after which every interface of a skillset was read again (link cut, server gone)
    bad: Counter[str] = field(default_factory=Counter)  # other bad input, per kind


@dataclass
class _Skillset:
    binding: Binding
    deriver: bound.BoundDeriver
    seq: int = 0
    reported: set[str] = field(default_factory=set)
    slot: Slot | None = None  # its place in the order while it waits for a result
    unread: dict[str, str] = field(default_factory=dict)  # interface -> why it must be read again
    gap: tuple[str, SkillsetStatus | None] | None = None  # why the first went unread, and the status then


class BoundFeed:
    """Derivation state of every bound skillset of ``system`` (not thread-safe).

    ``synced``: start from the model's initial marking (replay) instead of reading
    every interface first (live); ``results``: whether results can be fetched.
    """

    def __init__(self, system: System, bindings: Mapping[str, Binding], source: str, *, synced: bool = False,
                 results: bool = True, epoch: int | None = None, order: Order | None = None):
        self.system = system
        self.source = source
        self.order = Order() if order is None else order  # shared with the managers' feed, if any
        self.epoch = time.time_ns() // 1_000_000 if epoch is None else epoch
        self.counters = BoundCounters()
        self.drifts: list[bound.Drift] = []
        self.requests: list[tuple[str, bound.ResultRequest]] = []  # results to fetch (live)
        self.skillsets = {name: _Skillset(b, bound.BoundDeriver(system.component(name), b, synced=synced,
                                                                results=results))
                          for name, b in bindings.items()}
        self.routes: dict[str, list[Route]] = {}  # ROS topic name -> what it feeds
        # skillset -> interface (status topic, lifecycle node, resource topic) -> what reading it means
        self.interfaces: dict[str, dict[str, str]] = {}
        for name, b in bindings.items():
            reads = self.interfaces[name] = {}
            for s in b.skills:
                self._route(s.name("status"), Route(name, "status", STATUS_TYPE, s.skill, s.name("status")))
                reads[s.name("status")] = f"the status of {s.action}"
            for r in b.resources:
                if r.lifecycle:
                    self._route(r.transition_event, Route(name, "lifecycle", TRANSITION_EVENT_TYPE, r.resource,
                                                          r.lifecycle))
                    reads[r.lifecycle] = f"the state of {r.lifecycle}"
                else:
                    reads[r.topic] = f"a new {r.topic} message"
            for topic, typename in b.topics().items():
                if not any(r.skillset == name for r in self.routes.get(topic, [])):
                    self._route(topic, Route(name, "topic", typename, reads=topic if topic in reads else ""))

    def _route(self, topic: str, route: Route) -> None:
        self.routes.setdefault(topic, []).append(route)

    def feed(self, topic: str, payload: bytes, stamp: float) -> list[CanonicalEvent]:
        """Canonical events caused by one CDR message of a bound topic (its ROS name): those whose turn
        has come (:meth:`Order.drain`), of any skillset of the order."""
        self.counters.messages += 1
        for route in self.routes.get(topic, []):
            ss = self.skillsets[route.skillset]
            try:
                msg = to_plain(decode(ss.binding.store, route.typename, payload))
                if route.kind == "status":
                    out = ss.deriver.on_status(route.owner, bound.goals_from_plain(msg), stamp)
                elif route.kind == "lifecycle":
                    out = ss.deriver.on_transition_event(route.owner, int(msg["start_state"]["id"]),
                                                         int(msg["goal_state"]["id"]), stamp)
                else:
                    out = ss.deriver.on_topic(topic, msg, stamp)
            except Exception as exc:  # rosbags raises several types on bad CDR; views raise KeyError
                self.counters.malformed += 1
                self._bad(ss, f"malformed {topic}", f"{topic}: message dropped, it does not decode as "
                                                    f"{route.typename} ({type(exc).__name__}: {exc})", count=False)
                continue
            self._emit(route.skillset, out)
            settled = route.kind != "lifecycle" or 1 <= int(msg["goal_state"]["id"]) <= 4
            if route.reads and settled:
                self._read(route.skillset, route.reads, stamp)
        return self.order.drain()

    def result(self, skillset: str, request: bound.ResultRequest, payload: bytes | None,
               stamp: float) -> list[CanonicalEvent]:
        """The reply of ``get_result`` for ``request`` (``None``: no reply in time)."""
        ss = self.skillsets[skillset]
        result = None
        if payload is not None:
            try:
                status, result = get_result_reply(ss.binding.store, request.type, payload)
            except Exception as exc:  # a reply that does not decode: the default mode, said so
                self._bad(ss, "malformed result", f"{request.action}/_action/get_result: reply does not decode "
                                                  f"({type(exc).__name__}: {exc})")
                result = None
            else:
                if status not in bound.TERMINAL:
                    self._bad(ss, "result not terminal", f"{request.action}/_action/get_result: goal "
                                                         f"{bound.goal_text(request.goal)} answered with status "
                                                         f"{bound.STATUS_NAMES.get(status, status)}")
        self._emit(skillset, ss.deriver.on_result(request.skill, request.goal, result, stamp))
        return self.order.drain()

    def lifecycle_state(self, skillset: str, resource: str, payload: bytes, stamp: float) -> list[CanonicalEvent]:
        """The reply of a lifecycle node's ``get_state``."""
        ss = self.skillsets[skillset]
        try:
            state, _ = get_state_reply(ss.binding.store, payload)
        except Exception as exc:
            self._bad(ss, "malformed get_state", f"get_state of {resource}: reply does not decode "
                                                 f"({type(exc).__name__}: {exc})")
            return self.order.drain()
        self._emit(skillset, ss.deriver.on_lifecycle_state(resource, state, stamp))
        self._read(skillset, next(r.lifecycle for r in ss.binding.resources if r.resource == resource), stamp)
        return self.order.drain()

    def no_status(self, skillset: str, skill: str, stamp: float) -> list[CanonicalEvent]:
        """``skill``'s action server is up and its status cache is empty: no goal yet (once synced: the
        server forgot every goal, it restarted)."""
        ss = self.skillsets[skillset]
        d = ss.deriver
        self._emit(skillset, d.on_status(skill, [], stamp) if d.synced else d.no_status(skill, stamp))
        self._read(skillset, d.actions[skill].binding.name("status"), stamp)
        return self.order.drain()

    # -- what the bridge can vouch for ------------------------------------------------------

    def unread(self, skillset: str, why: str, interfaces: list[str] | None = None) -> None:
        """The readings of ``interfaces`` (default: all) of ``skillset`` may be outdated, because ``why``
        (the link was cut, a server or node left): each must be read again before its status is current.
        Nothing to do before the first status (start-up reads everything anyway)."""
        ss = self.skillsets[skillset]
        if not ss.deriver.synced:
            return
        for i in self.interfaces[skillset] if interfaces is None else interfaces:
            if interfaces is None or i not in ss.unread:  # a cut link is the stronger news
                ss.unread[i] = why
        if ss.gap is None and ss.unread:
            ss.gap = (why, ss.deriver.status())
        elif ss.gap is not None and interfaces is None:
            ss.gap = (why, ss.gap[1])
            log.warning("%s: %s; waiting for %s", skillset, why, ", ".join(self.interfaces[skillset][i]
                                                                          for i in ss.unread))

    def _read(self, skillset: str, interface: str, stamp: float) -> None:
        """``interface`` was read: the gap it was part of closes with the last one (an event says so)."""
        ss = self.skillsets[skillset]
        if ss.unread.pop(interface, None) is None or ss.unread or ss.gap is None:
            return
        (why, before), ss.gap = ss.gap, None
        self.counters.resyncs += 1
        now = ss.deriver.status()
        diverged = differences(before, now) if before is not None and now is not None else ""
        info = f"resync after {why}; " + (f"state now differs: {diverged}" if diverged else "same state as before")
        log.warning("%s: %s", skillset, info)
        self._emit(skillset, bound.BoundOutput([Derived(None, now, stamp, info)]))

    def pending(self, skillset: str) -> str:
        """Why ``skillset``'s status is not current ('' when it is): start-up readings still missing, or
        interfaces to read again (docs/semantics.md §7: nobody may vouch for it meanwhile)."""
        ss = self.skillsets[skillset]
        if not ss.deriver.synced:
            return f"waiting for {', '.join(ss.deriver.missing())}"
        reasons: dict[str, list[str]] = {}
        for interface, why in ss.unread.items():
            reasons.setdefault(why, []).append(self.interfaces[skillset][interface])
        return "; ".join(f"{why}: waiting for {', '.join(what)}" for why, what in reasons.items())

    def pending_results(self) -> list[tuple[str, bound.ResultRequest]]:
        """Results the derivation waits for (skillset, request)."""
        out = []
        for name, ss in self.skillsets.items():
            waiting = ss.deriver.waiting
            if waiting is not None:
                out.append((name, waiting))
        return out

    def _emit(self, skillset: str, out: bound.BoundOutput) -> None:
        """Number ``out``'s events and place them in the order: in the skillset's slot while it waits for a
        result (opened when the wait begins, closed when it ends)."""
        ss = self.skillsets[skillset]
        for note in out.notes:
            log.info("%s", note)
        for kind, message in out.bad:
            self._bad(ss, kind, message)
        derived = list(out.events)
        carried = {d.divergence for d in derived}
        for drift in out.drifts:
            self.counters.drifts += 1
            self.drifts.append(drift)
            log.warning("%s: model divergence: %s", skillset, drift)
            status = ss.deriver.status()
            if str(drift) not in carried and status is not None:  # nothing moved: published all the same
                derived.append(Derived(None, status, drift.stamp, f"model divergence: {drift}", str(drift)))
        self.requests += [(skillset, r) for r in out.results]
        events = []
        for d in derived:
            events.append(CanonicalEvent(system=self.system.name, skillset=skillset, seq=ss.seq, stamp=d.stamp,
                                         source=self.source, epoch=self.epoch, transition=d.transition,
                                         status=d.status, info=d.info, divergence=d.divergence))
            ss.seq += 1
        self.counters.events += len(events)
        if ss.slot is not None:
            ss.slot.events += events
        else:
            self.order.place(events)
        waiting = ss.deriver.waiting is not None
        if waiting and ss.slot is None:
            ss.slot = self.order.open()
        elif not waiting and ss.slot is not None:
            self.order.close(ss.slot)
            ss.slot = None

    def take_requests(self) -> list[tuple[str, bound.ResultRequest]]:
        """Results asked for since the last call (the live bridge fetches them with ``get_result``)."""
        out, self.requests = self.requests, []
        return out

    def _bad(self, ss: _Skillset, kind: str, message: str, count: bool = True) -> None:
        """Count bad input of ``kind``; log it the first time it shows up for this skillset."""
        if count:
            self.counters.bad[kind] += 1
        if kind not in ss.reported:
            ss.reported.add(kind)
            log.warning("%s: %s (reported once per kind; see the bridge's counters)", ss.binding.skillset, message)

    def last_status(self, skillset: str) -> CanonicalEvent | None:
        """A status-only event with ``skillset``'s status, numbered as its last event (resync)."""
        ss = self.skillsets[skillset]
        status = ss.deriver.status()
        if status is None:
            return None
        return CanonicalEvent(system=self.system.name, skillset=skillset, seq=max(ss.seq - 1, 0), stamp=time.time(),
                              source=self.source, epoch=self.epoch, status=status, info="resync")

    def missing(self) -> dict[str, list[str]]:
        """What each skillset still waits for at start-up (empty lists once synced)."""
        return {name: ss.deriver.missing() for name, ss in self.skillsets.items()}


# -- replay ---------------------------------------------------------------------------------------


@dataclass
class Replayed:
    """What a replay went through: the feeds (counters, drifts) and the bag's first and last times."""

    bound: BoundFeed | None
    managers: Feed | None
    start: float | None = None
    end: float | None = None
    unrecorded: list[str] = field(default_factory=list)  # bound topics the bag lacks


def replay_bags(path: str | Path, system: System, typemap: Mapping[str, str], bindings: Mapping[str, Binding],
                emit: Callable[[CanonicalEvent], None], *, source: str = "bridge_ros2/replay",
                realtime: bool = False, hold: float = 0.5) -> Replayed:
    """Feed every manager and bound topic of the bag at ``path`` in time order; returns the feeds.

    A bound topic recorded with another type than the binding's is a
    :class:`SourceError` at the bag, before anything is fed.  Raises ``rosbags``
    errors when the bag cannot be read.
    """
    from rosbags.highlevel import AnyReader

    managed = [c for c in system.components if not c.binding]
    order = Order()  # both kinds in the order of the bag
    feed = Feed(system, typemap, source, hold=hold, order=order) if managed else None
    bound_feed = BoundFeed(system, bindings, source, synced=True, results=False, order=order) if bindings else None
    manager_routes = feed.by_fqn() if feed is not None else {}
    bound_routes = bound_feed.routes if bound_feed is not None else {}
    out = Replayed(bound_feed, feed)
    with AnyReader([Path(path)]) as reader:
        for conn in reader.connections:
            for route in bound_routes.get(conn.topic, []):
                if conn.msgtype != route.typename:
                    raise SourceError.at(str(path), None, f"topic {conn.topic} is recorded as {conn.msgtype}; the "
                                                          f"binding of {route.skillset} reads it as {route.typename}")
        recorded = {c.topic for c in reader.connections}
        out.unrecorded = [t for t in bound_routes if t not in recorded]
        connections = [c for c in reader.connections if c.topic in manager_routes or c.topic in bound_routes]
        first: int | None = None
        origin = time.monotonic()
        for conn, timestamp, raw in reader.messages(connections=connections):
            first = timestamp if first is None else first
            if realtime:
                delay = origin + (timestamp - first) * 1e-9 - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            stamp = timestamp * 1e-9
            out.start = stamp if out.start is None else out.start
            out.end = stamp
            if conn.topic in bound_routes and bound_feed is not None:
                events = bound_feed.feed(conn.topic, bytes(raw), stamp)
            else:
                assert feed is not None
                skillset, topic = manager_routes[conn.topic]
                events = feed.feed(skillset, topic, bytes(raw)) + feed.expire()
            for ev in events:
                emit(ev)
    for ev in feed.flush() if feed is not None else []:
        emit(ev)
    return out


__all__ = ["BoundCounters", "BoundFeed", "Replayed", "Route", "replay_bags"]
