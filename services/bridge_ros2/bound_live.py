"""bridge_ros2 for bound skillsets on Zenoh: action servers, lifecycle nodes and topics in, canonical events out.

SPEC §9.  For every binding of the system, on the keys of :class:`~skinet.ros.keys.KeyStyle`
(``zenoh-bridge-ros2dds``: the ROS name without its leading slash, below the bridge's
namespace; ``rmw_zenoh``: ``<domain>/<name>/<DDS type>/<type hash>``):

- each action's ``<action>/_action/status`` (``GoalStatusArray``) with an advanced
  subscriber that also fetches the last status from the publisher's cache (the topic
  is transient local: both gateways keep its last sample in a zenoh-ext cache, and
  answer late subscribers and publishers detected later);
- each lifecycle node's ``<node>/transition_event``, and its ``<node>/get_state``
  service, asked at start-up (and again every ``retry`` seconds until it answers);
- each bound topic.

Start-up (SPEC §9): a skillset is *syncing* until each of its interfaces has been
read; nothing is published for it before.  An action whose server is present
(``zenoh-bridge-ros2dds``: the route's ``AS`` liveliness token; ``rmw_zenoh``: the
``send_goal`` service token) and has published no status is read as "no goal" once
``settle`` seconds have passed and a query of its status cache returned nothing.
When a terminal goal's mode depends on its result, the bridge asks
``<action>/_action/get_result`` and holds that skillset's later observations until
the reply (at most ``hold`` seconds: then the binding's default mode, said so).

The callbacks only queue; one worker thread derives, in arrival order.  The bridge
never stops on bad input (counted, logged once per kind: :class:`BoundFeed`).
"""

from __future__ import annotations

import logging
import os
import queue
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import zenoh
import zenoh.ext as zext

from services.bridge_ros2.bound import BoundCounters, BoundFeed
from services.common.cli import default_instance_id
from services.common.events import event_publisher
from services.common.heartbeat import HeartbeatPublisher
from services.common.zenoh_config import undeclare
from skinet.ros import bound
from skinet.ros.actions import get_result_request, get_state_request
from skinet.ros.binding import GET_STATE_TYPE, STATUS_TYPE, Binding
from skinet.ros.keys import KeyStyle, history_selector, parse_liveliness_token, rmw_attachment
from skinet.system import System
from skinet.wire import keys
from skinet.wire.codec import encode as wire_encode
from skinet.wire.messages import HeartbeatSkillset

log = logging.getLogger("skinet.bridge_ros2")

PLUGIN_SERVERS = "@/*/@ros2_lv/AS/**"  # zenoh-bridge-ros2dds: one token per route to a DDS action server


class BoundBridge:
    """A running bridge for the bound skillsets of ``system``; see the module docstring."""

    def __init__(self, session: zenoh.Session, system: System, bindings: Mapping[str, Binding], *,
                 style: KeyStyle = KeyStyle(), instance_id: str | None = None, source: str | None = None,
                 hold: float = 0.5, settle: float = 0.5, retry: float = 1.0):
        self.session = session
        self.system = system
        self.style = style
        self.hold = hold
        self.settle = settle
        self.retry = retry
        self.instance_id = keys.check_chunk(instance_id or default_instance_id(), "instance id")
        self.feed = BoundFeed(system, bindings, source or f"bridge_ros2/{self.instance_id}")
        self._queue: queue.SimpleQueue[Callable[[], list] | None] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._sequence = 0
        self._gid = os.urandom(16)
        self._present: dict[tuple[str, str], float] = {}  # (skillset, skill) -> when its server was seen
        self._events = {name: event_publisher(session, keys.events(system.name, name)) for name in bindings}
        self._subscribers: list[Any] = []
        for topic, routes in self.feed.routes.items():
            key = style.name_key(topic, routes[0].typename)
            handler = zenoh.handlers.Callback(self._on_sample(topic), indirect=False)
            if any(r.kind == "status" for r in routes):
                self._subscribers.append(zext.declare_advanced_subscriber(
                    session, key, handler, history=zext.HistoryConfig(detect_late_publishers=True)))
            else:
                self._subscribers.append(session.declare_subscriber(key, handler))
        self._subscribers.append(session.liveliness().declare_subscriber(
            f"@ros2_lv/{style.domain}/**" if style.rmw_zenoh else PLUGIN_SERVERS, self._on_token, history=True))
        self._resync = [session.declare_queryable(keys.resync(system.name, name), self._on_resync)
                        for name in bindings]
        token = keys.alive(system.name, "bridge_ros2", self.instance_id)
        self._token = session.liveliness().declare_token(token)
        self._heartbeat = HeartbeatPublisher(  # SPEC §7: the monitor loses what a silent bridge publishes
            session, system.name, self.feed.source, self.feed.epoch, token,
            lambda: {n: HeartbeatSkillset(seq=s.seq - 1 if s.seq else None) for n, s in self.feed.skillsets.items()})
        self._worker = threading.Thread(target=self._run, name="bridge_ros2-bound", daemon=True)
        self._worker.start()
        self._asker = threading.Thread(target=self._start_up, name="bridge_ros2-bound-start", daemon=True)
        self._asker.start()
        log.info("bound skillsets of %s (%s keys): %s; waiting for %s", system.name,
                 "rmw_zenoh" if style.rmw_zenoh else "zenoh-bridge-ros2dds", ", ".join(bindings),
                 "; ".join(f"{n}: {', '.join(m)}" for n, m in self.feed.missing().items() if m) or "nothing")

    @property
    def counters(self) -> BoundCounters:
        return self.feed.counters

    # -- work on the worker thread ----------------------------------------------------------

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                for ev in item():
                    self._events[ev.skillset].put(wire_encode(ev))
                for skillset, request in self.feed.take_requests():
                    self._ask_result(skillset, request)
            except Exception:  # a bug must not stop the bridge (SPEC §7)
                log.exception("failed to handle a bound message")

    def _on_sample(self, topic: str) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            payload, stamp = sample.payload.to_bytes(), time.time()
            self._queue.put(lambda: self.feed.feed(topic, payload, stamp))

        return on_sample

    def wait_idle(self, timeout: float = 5.0) -> bool:
        """Wait until every queued message has been handled (tests, the embedded demo)."""
        marker = threading.Event()
        self._queue.put(lambda: marker.set() or [])
        return marker.wait(timeout)

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
            self._queue.put(lambda: self.feed.result(skillset, request, reply, stamp))

        self._service_get(f"{request.action}/_action/get_result", f"{request.type}_GetResult", payload, done,
                          max(self.hold, 0.01))

    def _start_up(self) -> None:
        """Until every bound skillset is synced: ask lifecycle nodes their state, and read the status
        cache of each action whose server is present."""
        while not self._stop.is_set():
            try:  # read from this thread while the worker derives: a snapshot is enough to decide what to ask
                missing = self.feed.missing()
            except RuntimeError:  # a dict changed size meanwhile
                continue
            if not any(missing.values()):
                return
            for name, ss in self.feed.skillsets.items():
                if not missing.get(name):
                    continue
                for r in ss.binding.resources:
                    if r.lifecycle and r.resource not in ss.deriver.readings:
                        self._ask_state(name, r.resource, r.get_state, ss.binding)
                for skill, action in ss.deriver.actions.items():
                    seen = self._present.get((name, skill))
                    if not action.read and seen is not None and time.monotonic() - seen >= self.settle:
                        self._read_cache(name, skill, action.binding.name("status"))
            self._stop.wait(self.retry)

    def _ask_state(self, skillset: str, resource: str, service: str, binding: Binding) -> None:
        def done(reply: bytes | None) -> None:
            if reply is not None:
                stamp = time.time()
                self._queue.put(lambda: self.feed.lifecycle_state(skillset, resource, reply, stamp))

        self._service_get(service, GET_STATE_TYPE, get_state_request(binding.store), done, self.retry)

    def _read_cache(self, skillset: str, skill: str, topic: str) -> None:
        """The last status from the publishers' caches; none while the server is up: no goal yet."""
        key = self.style.name_key(topic, STATUS_TYPE)
        samples = [r.ok.payload.to_bytes() for r in self.session.get(
            history_selector(key), accept_replies=zenoh.ReplyKeyExpr.ANY, timeout=self.retry) if r.ok is not None]
        stamp = time.time()
        if samples:
            self._queue.put(lambda: [ev for s in samples for ev in self.feed.feed(topic, s, stamp)])
        else:
            self._queue.put(lambda: self.feed.no_status(skillset, skill, stamp))

    def _on_token(self, sample: zenoh.Sample) -> None:
        """An action server appeared (or left): its status cache may be read after ``settle`` seconds."""
        key = str(sample.key_expr)
        for name, ss in self.feed.skillsets.items():
            for s in ss.binding.skills:
                if self._serves(key, s.action):
                    if sample.kind == zenoh.SampleKind.PUT:
                        self._present.setdefault((name, s.skill), time.monotonic())
                    else:
                        self._present.pop((name, s.skill), None)

    def _serves(self, token: str, action: str) -> bool:
        if self.style.rmw_zenoh:
            entity = parse_liveliness_token(token)
            return entity is not None and entity.kind == "SS" and entity.topic == f"{action}/_action/send_goal"
        parts = token.split("/")  # @/<zid>/@ros2_lv/AS/<key with / as §>/<type>
        return len(parts) >= 5 and parts[3] == "AS" and \
            parts[4].replace("§", "/") == self.style.name_key(action, "")

    def _on_resync(self, query: zenoh.Query) -> None:
        with query:
            skillset = str(query.key_expr).rsplit("/", 1)[-1]
            if skillset not in self.feed.skillsets:
                return
            ev = self.feed.last_status(skillset)  # a snapshot; the worker may move on meanwhile
            if ev is not None:
                query.reply(keys.resync(self.system.name, skillset), wire_encode(ev))

    def close(self) -> None:
        """Stop asking, let the worker finish what is queued, undeclare everything."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._heartbeat.close()
        undeclare(self._token, *self._resync, *self._subscribers)
        self._queue.put(None)
        self._worker.join(5.0)
        self._asker.join(5.0)
        undeclare(*self._events.values())


def start_bound_bridge(session: zenoh.Session, system: System, bindings: Mapping[str, Binding],
                       **options: Any) -> BoundBridge:
    """Start a bridge for the bound skillsets of ``system`` on ``session``; options as :class:`BoundBridge`."""
    return BoundBridge(session, system, bindings, **options)


__all__ = ["BoundBridge", "start_bound_bridge"]
