"""bridge_ros2 for bound skillsets on Zenoh: action servers, lifecycle nodes and topics in, canonical events out.

docs/semantics.md §9.  For every binding of the system, on the keys of :class:`~skinet.ros.keys.KeyStyle`
(``zenoh-bridge-ros2dds``: the ROS name without its leading slash, below the bridge's
namespace; ``rmw_zenoh``: ``<domain>/<name>/<DDS type>/<type hash>``):

- each action's ``<action>/_action/status`` (``GoalStatusArray``) with an advanced
  subscriber that also fetches the last status from the publisher's cache (the topic
  is transient local: both gateways keep its last sample in a zenoh-ext cache, and
  answer late subscribers and publishers detected later);
- each lifecycle node's ``<node>/transition_event``, and its ``<node>/get_state``
  service, asked at start-up (and again every ``retry`` seconds until it answers);
- each bound topic.

Start-up (docs/semantics.md §9): a skillset is *syncing* until each of its interfaces has been
read; nothing is published for it before.  An action whose server is present
(``zenoh-bridge-ros2dds``: the route's ``AS`` liveliness token; ``rmw_zenoh``: the
``send_goal`` service token) and has published no status is read as "no goal" once
``settle`` seconds have passed and a query of its status cache returned nothing.
When a terminal goal's mode depends on its result, the bridge asks
``<action>/_action/get_result`` and holds that skillset's later observations until
the reply (at most ``hold`` seconds: then the binding's default mode, said so).

Honest status (docs/semantics.md §7): while a skillset's status is pending (start-up readings
missing; after the link to the routers was cut, every interface; after an action
server or a lifecycle node left, as its token shows (``SS`` route token of its
``get_state`` service, or the ``rmw_zenoh`` service token), its own), the heartbeat
lists it as ``pending`` with why (sent at once when that changes) and resync
queries get an error reply saying so.  The reader thread reads each such interface
again once it can (its server back and settled, its node asked ``get_state``, the
link back); a bound topic is read again by its next sample.

The callbacks only queue; one worker thread derives, in arrival order
(:class:`~services.bridge_ros2.worker.Worker`, shared with the managers' bridge of
the same process).  The bridge never stops on bad input (counted, logged once per
kind: :class:`BoundFeed`).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import zenoh
import zenoh.ext as zext

from services.bridge_ros2.bound import BoundCounters, BoundFeed
from services.bridge_ros2.link import watch_link
from services.bridge_ros2.worker import Worker
from services.common.cli import default_instance_id
from services.common.events import event_publisher
from services.common.heartbeat import refusal
from services.common.zenoh_config import undeclare
from skinet.ros import bound
from skinet.ros.actions import get_result_request, get_state_request
from skinet.ros.binding import GET_STATE_TYPE, STATUS_TYPE, Binding
from skinet.ros.keys import KeyStyle, history_selector, parse_liveliness_token, rmw_attachment
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import encode as wire_encode
from skinet.wire.messages import HeartbeatSkillset

log = logging.getLogger("skinet.bridge_ros2")

PLUGIN_SERVERS = "@/*/@ros2_lv/AS/**"  # zenoh-bridge-ros2dds: one token per route to a DDS action server
PLUGIN_SERVICES = "@/*/@ros2_lv/SS/**"  # ... and per route to a DDS service server (a lifecycle node's get_state)
CUT = "the link to the robot's interfaces was cut"


class BoundBridge:
    """A running bridge for the bound skillsets of ``system``; see the module docstring.  ``worker``: the
    derivation thread to share with the managers' bridge of the same process; by default its own."""

    def __init__(self, session: zenoh.Session, system: System, bindings: Mapping[str, Binding], *,
                 style: KeyStyle = KeyStyle(), instance_id: str | None = None, source: str | None = None,
                 hold: float = 0.5, settle: float = 0.5, retry: float = 1.0, worker: Worker | None = None):
        self.session = session
        self.system = system
        self.style = style
        self.hold = hold
        self.settle = settle
        self.retry = retry
        self.instance_id = keys.check_chunk(instance_id or default_instance_id(), "instance id")
        self.worker = Worker("bridge_ros2-bound") if worker is None else worker
        self._own_worker = worker is None
        self.feed = BoundFeed(system, bindings, source or f"bridge_ros2/{self.instance_id}", epoch=self.worker.epoch,
                              order=self.worker.order)
        self._stop = threading.Event()
        self._link = threading.Event()  # set while the session reaches a router (reads go nowhere else)
        self._link.set()
        self._sequence = 0
        self._gid = os.urandom(16)
        self._present: dict[tuple[str, str], float] = {}  # (skillset, skill) -> when its server was seen
        self._nodes: dict[tuple[str, str], str] = {}  # (skillset, resource) -> token of its node's get_state
        self._events = {name: event_publisher(session, keys.events(system.name, name)) for name in bindings}
        self.worker.publishers.update(self._events)
        self._subscribers: list[Any] = []
        for topic, routes in self.feed.routes.items():
            key = style.name_key(topic, routes[0].typename)
            handler = zenoh.handlers.Callback(self._on_sample(topic), indirect=False)
            if any(r.kind == "status" for r in routes):
                self._subscribers.append(zext.declare_advanced_subscriber(
                    session, key, handler, history=zext.HistoryConfig(detect_late_publishers=True)))
            else:
                self._subscribers.append(session.declare_subscriber(key, handler))
        for tokens in [f"@ros2_lv/{style.domain}/**"] if style.rmw_zenoh else [PLUGIN_SERVERS, PLUGIN_SERVICES]:
            self._subscribers.append(session.liveliness().declare_subscriber(tokens, self._on_token, history=True))
        self._resync = [session.declare_queryable(keys.resync(system.name, name), self._on_resync)
                        for name in bindings]
        self._pending_seen: dict[str, str] = {}  # what the last heartbeat said was pending (see _notice)
        # docs/semantics.md §7: the monitor loses what a silent bridge publishes.
        self._heartbeat = self.worker.beacon(session, system.name, self.feed.source, self.instance_id, self._beat,
                                             self._pending)
        self.worker.add_follow_up(self._ask_results)
        self.worker.add_follow_up(self._notice)
        self._asker = threading.Thread(target=self._read_again, name="bridge_ros2-bound-read", daemon=True)
        self._asker.start()
        self._linker = threading.Thread(target=watch_link, args=(session, self._stop, self._on_cut, self._link.set),
                                        name="bridge_ros2-bound-link", daemon=True)
        self._linker.start()
        log.info("bound skillsets of %s (%s keys): %s; waiting for %s", system.name,
                 "rmw_zenoh" if style.rmw_zenoh else "zenoh-bridge-ros2dds", ", ".join(bindings),
                 "; ".join(f"{n}: {', '.join(m)}" for n, m in self.feed.missing().items() if m) or "nothing")

    @property
    def counters(self) -> BoundCounters:
        return self.feed.counters

    # -- work on the worker thread ----------------------------------------------------------

    def _ask_results(self) -> None:
        for skillset, request in self.feed.take_requests():
            self._ask_result(skillset, request)

    def _on_sample(self, topic: str) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            payload, stamp = sample.payload.to_bytes(), time.time()
            self.worker.put(lambda: self.feed.feed(topic, payload, stamp))

        return on_sample

    def wait_idle(self, timeout: float = 5.0) -> bool:
        """Wait until every queued message has been handled (tests, the embedded demo)."""
        return self.worker.wait_idle(timeout)

    # -- what it can vouch for (docs/semantics.md §7) -----------------------------------------------------

    def _beat(self) -> dict[str, HeartbeatSkillset]:
        """Per skillset, the seq of its last event (the heartbeat)."""
        return {n: HeartbeatSkillset(seq=s.seq - 1 if s.seq else None) for n, s in self.feed.skillsets.items()}

    def _pending(self) -> dict[str, str]:
        """The heartbeat's ``pending``: skillsets whose status is not current, with why."""
        with self.worker.lock:
            return {n: why for n in self.feed.skillsets if (why := self.feed.pending(n))}

    def _notice(self) -> None:
        """Send a heartbeat at once when what is pending changed."""
        pending = self._pending()
        if pending != self._pending_seen:
            self._pending_seen = pending
            self._heartbeat.poke()

    def _unread(self, skillset: str, why: str, interfaces: list[str] | None = None) -> None:
        """Queue :meth:`BoundFeed.unread` behind the messages received so far (and tell the monitors)."""
        self.worker.put(lambda: self.feed.unread(skillset, why, interfaces) or [])

    def _on_cut(self) -> None:
        """The session lost every router: every reading may be outdated, each is read again once it is back."""
        self._link.clear()
        log.warning("link to the router(s) lost: messages of the bound interfaces may be lost until it is back")
        for name in self.feed.skillsets:
            self._unread(name, CUT)

    # -- services: get_result, get_state ----------------------------------------------------

    def _service_get(self, name: str, typename: str, payload: bytes, on_done: Callable[[bytes | None], None],
                     timeout: float) -> None:
        """Call a ROS 2 service through the gateway; ``on_done`` gets the reply's payload or None."""
        attachment = None
        if self.style.rmw_zenoh:  # rmw_zenoh servers read the client's GID and sequence number from it
            self._sequence += 1
            attachment = rmw_attachment(self._sequence, time.time_ns(), self._gid)
        replies: list[bytes] = []

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None and not replies:
                replies.append(reply.ok.payload.to_bytes())

        self.session.get(self.style.name_key(name, typename), zenoh.handlers.Callback(
            on_reply, lambda: on_done(replies[0] if replies else None)), payload=payload, attachment=attachment,
            timeout=timeout)

    def _ask_result(self, skillset: str, request: bound.ResultRequest) -> None:
        store = self.feed.skillsets[skillset].binding.store
        payload = get_result_request(store, request.type, request.goal)

        def done(reply: bytes | None) -> None:
            if reply is None:
                log.warning("%s: no reply from %s/_action/get_result within %.2f s", skillset, request.action,
                            self.hold)
            stamp = time.time()
            self.worker.put(lambda: self.feed.result(skillset, request, reply, stamp))

        self._service_get(f"{request.action}/_action/get_result", f"{request.type}_GetResult", payload, done,
                          max(self.hold, 0.01))

    def _read_again(self) -> None:
        """Until the bridge stops: read what a skillset waits for (at start-up, or after a gap): ask
        lifecycle nodes their state, read the status cache of each action whose server is present and
        settled; nothing while the link is cut (the reads would go nowhere)."""
        while not self._stop.is_set():
            if not self._link.is_set():
                self._stop.wait(self.retry)
                continue
            with self.worker.lock:  # a snapshot of what to read; the reads are asynchronous
                todo = [(name, ss.binding, set(ss.unread), {r for r in ss.deriver.readings},
                         {k for k, a in ss.deriver.actions.items() if a.read}, ss.deriver.synced)
                        for name, ss in self.feed.skillsets.items()]
            for name, binding, unread, readings, read, synced in todo:
                for r in binding.resources:
                    if r.lifecycle and (r.lifecycle in unread if synced else r.resource not in readings):
                        self._ask_state(name, r.resource, r.get_state, binding)
                for s in binding.skills:
                    seen = self._present.get((name, s.skill))
                    wanted = s.name("status") in unread if synced else s.skill not in read
                    if wanted and seen is not None and time.monotonic() - seen >= self.settle:
                        self._read_cache(name, s.skill, s.name("status"))
            self._stop.wait(self.retry)

    def _ask_state(self, skillset: str, resource: str, service: str, binding: Binding) -> None:
        def done(reply: bytes | None) -> None:
            if reply is not None:
                stamp = time.time()
                self.worker.put(lambda: self.feed.lifecycle_state(skillset, resource, reply, stamp))

        self._service_get(service, GET_STATE_TYPE, get_state_request(binding.store), done, self.retry)

    def _read_cache(self, skillset: str, skill: str, topic: str) -> None:
        """The last status from the publishers' caches; none while the server is up: no goal yet."""
        key = self.style.name_key(topic, STATUS_TYPE)
        samples = [r.ok.payload.to_bytes() for r in self.session.get(
            history_selector(key), accept_replies=zenoh.ReplyKeyExpr.ANY, timeout=self.retry) if r.ok is not None]
        stamp = time.time()
        if samples:
            self.worker.put(lambda: [ev for s in samples for ev in self.feed.feed(topic, s, stamp)])
        else:
            self.worker.put(lambda: self.feed.no_status(skillset, skill, stamp))

    def _on_token(self, sample: zenoh.Sample) -> None:
        """An action server appeared (its status cache may be read after ``settle`` seconds) or left (its
        status must be read again once it is back); a lifecycle node appeared or left (likewise)."""
        key, put = str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT
        for name, ss in self.feed.skillsets.items():
            for s in ss.binding.skills:
                if self._serves(key, s.action, "_action/send_goal", "AS"):
                    if put:
                        self._present.setdefault((name, s.skill), time.monotonic())
                    elif self._present.pop((name, s.skill), None) is not None:
                        self._unread(name, f"the action server of {s.action} left", [s.name("status")])
            for r in ss.binding.resources:
                if r.lifecycle and self._serves(key, r.get_state, "", "SS"):
                    if put:
                        self._nodes[(name, r.resource)] = key
                    elif self._nodes.get((name, r.resource)) == key:
                        del self._nodes[(name, r.resource)]
                        self._unread(name, f"the lifecycle node {r.lifecycle} left", [r.lifecycle])

    def _serves(self, token: str, name: str, service: str, plugin_kind: str) -> bool:
        """Whether ``token`` announces the server of ``name`` (an action: its ``service``; a service)."""
        if self.style.rmw_zenoh:
            entity = parse_liveliness_token(token)
            return entity is not None and entity.kind == "SS" and \
                entity.topic == (f"{name}/{service}" if service else name)
        parts = token.split("/")  # @/<zid>/@ros2_lv/<AS|SS>/<key with / as §>/<type>
        return len(parts) >= 5 and parts[3] == plugin_kind and \
            parts[4].replace("§", "/") == self.style.name_key(name, "")

    def _on_resync(self, query: zenoh.Query) -> None:
        with query:
            skillset = str(query.key_expr).rsplit("/", 1)[-1]
            if skillset not in self.feed.skillsets:
                return
            with self.worker.lock:
                why = self.feed.pending(skillset)
                ev = None if why else self.feed.last_status(skillset)
            if why:  # never vouch for a status it knows is not current (docs/semantics.md §7)
                query.reply_err(refusal(self.feed.source, skillset, why))
            elif ev is not None:
                query.reply(keys.resync(self.system.name, skillset), wire_encode(ev))

    def close(self) -> None:
        """Stop asking, let the worker finish what is queued, undeclare everything."""
        if self._stop.is_set():
            return
        self._stop.set()
        self.worker.release(self._beat)
        undeclare(*self._resync, *self._subscribers)
        if self._own_worker:
            self.worker.close()
        else:
            self.worker.wait_idle()
        self._asker.join(5.0)
        self._linker.join(5.0)
        for name in self._events:
            self.worker.publishers.pop(name, None)
        undeclare(*self._events.values())


def start_bound_bridge(session: zenoh.Session, system: System, bindings: Mapping[str, Binding],
                       **options: Any) -> BoundBridge:
    """Start a bridge for the bound skillsets of ``system`` on ``session``; options as :class:`BoundBridge`."""
    return BoundBridge(session, system, bindings, **options)


__all__ = ["BoundBridge", "start_bound_bridge"]
