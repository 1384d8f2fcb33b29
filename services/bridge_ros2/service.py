"""bridge_ros2 on Zenoh: manager topics in, canonical events out (SPEC §1).

Subscribes to each manager's ``status``, ``event_request``, ``event_response`` and
``skill/<k>/response`` on the keys of :mod:`skinet.ros.keys` (as
``zenoh-bridge-ros2dds`` or ``rmw_zenoh`` carry them) and publishes the derived
:class:`~skinet.wire.messages.CanonicalEvent` on ``keys.events(system, skillset)``
with ``CongestionControl.BLOCK`` (ZENOH.md) and a cache from which a monitor
recovers what it missed during an outage (:mod:`services.common.events`).

The manager's status is volatile (corpus README): at start-up the bridge sends
``status_request`` and repeats it every second until each manager has answered.
A monitor that missed events asks ``keys.resync(system, skillset)``: the bridge
answers with the skillset's last status (numbered as its last event) and asks
the manager for a fresh one.

One subscriber per manager covers all its topics (``.../<skillset>_skillset/**``):
separate subscribers per key would run their callbacks on different threads and
lose the order between a response and the status that follows it.  The callback
only queues the samples; one worker thread feeds them in arrival order, so
derivation never runs on Zenoh's threads.
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

from services.bridge_ros2.feed import Counters, Feed
from services.common.cli import default_instance_id
from services.common.events import event_publisher
from services.common.zenoh_config import undeclare
from skinet.ros.keys import EMPTY_TYPE, KeyStyle, ManagerTopic, manager_topics, rmw_attachment
from skinet.ros.typestore import default_instance, encode
from skinet.system import System
from skinet.wire import keys
from skinet.wire.codec import encode as wire_encode

log = logging.getLogger("skinet.bridge_ros2")


def default_source(instance: str | None = None) -> str:
    """``bridge_ros2/<instance>``: a new stream of sequence numbers per run for the monitor."""
    return f"bridge_ros2/{instance or default_instance_id()}"


class Bridge:
    """A running bridge; see :func:`start_bridge`."""

    def __init__(self, session: zenoh.Session, system: System, typemap: Mapping[str, str], *,
                 style: KeyStyle = KeyStyle(), instance_id: str | None = None, source: str | None = None,
                 request_status: bool = True, retry: float = 0.5, extra_types: Mapping[str, str] | None = None):
        self.session = session
        self.system = system
        self.style = style
        self.instance_id = keys.check_chunk(instance_id or default_instance_id(), "instance id")
        self.feed = Feed(system, typemap, source or default_source(self.instance_id), extra_types)
        self._queue: queue.SimpleQueue[tuple[str, ManagerTopic, bytes] | None] = queue.SimpleQueue()
        self._fed = threading.Condition()
        self._stop = threading.Event()
        self._subscribers: list[Any] = []
        self._events: dict[str, Any] = {}
        self._requests: dict[str, tuple[Any, bytes]] = {}
        self._sequence = 0
        self._gid = os.urandom(16)  # rmw_zenoh attachments of the status requests
        for name, m in self.feed.managers.items():
            manager = m.component.manager
            self._events[name] = event_publisher(session, keys.events(system.name, name))
            watched = {t.topic: t for t in m.topics}
            self._subscribers.append(session.declare_subscriber(
                style.all_topics(manager, m.component.skillset), self._callback(name, manager, watched)))
            req = next(t for t in manager_topics(m.component.skillset) if t.kind == "status_request")
            pub = session.declare_publisher(style.key(manager, req, m.store),
                                            congestion_control=zenoh.CongestionControl.BLOCK)
            self._requests[name] = (pub, encode(m.store, EMPTY_TYPE, default_instance(m.store, EMPTY_TYPE)))
        self._resync = session.declare_queryable(keys.resync(system.name, "*"), self._on_resync)
        self._token = session.liveliness().declare_token(keys.alive(system.name, "bridge_ros2", self.instance_id))
        self._worker = threading.Thread(target=self._run, name="bridge_ros2", daemon=True)
        self._worker.start()
        self._asker = None
        if request_status:
            self._asker = threading.Thread(target=self._ask_status, args=(retry,), name="bridge_ros2-status",
                                           daemon=True)
            self._asker.start()
        log.info("bridge for %s: %s keys, events on %s", system.name,
                 "rmw_zenoh" if style.rmw_zenoh else "zenoh-bridge-ros2dds", keys.events(system.name, "*"))

    @property
    def counters(self) -> Counters:
        """Messages fed, events published, malformed payloads (updated by the worker thread)."""
        return self.feed.counters

    def _callback(self, skillset: str, manager: str,
                  watched: dict[str, ManagerTopic]) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            topic = watched.get(self.style.topic(manager, str(sample.key_expr)) or "")
            if topic is not None:
                self._queue.put((skillset, topic, sample.payload.to_bytes()))

        return on_sample

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                with self._fed:
                    events = self.feed.feed(*item)
                for ev in events:
                    self._events[ev.skillset].put(wire_encode(ev))
            except Exception:  # a bug must not stop the bridge (SPEC §7)
                log.exception("failed to handle a message of %s", item[0])
            with self._fed:
                self._fed.notify_all()

    def _on_resync(self, query: zenoh.Query) -> None:
        with query:
            skillset = str(query.key_expr).rsplit("/", 1)[-1]
            if skillset not in self.feed.managers:
                return
            with self._fed:
                ev = self.feed.last_status(skillset)
            if ev is not None:
                query.reply(keys.resync(self.system.name, skillset), wire_encode(ev))
            self.request_status(skillset)

    def wait_statuses(self, counts: Mapping[str, int], timeout: float = 5.0) -> bool:
        """Wait until ``counts[skillset]`` statuses of each skillset were handled and their events published.

        With :meth:`services.simulator.Simulator.statuses_published` this tells a test
        (or an embedded demo) that the bridge has caught up with the simulator.
        """
        with self._fed:
            return self._fed.wait_for(
                lambda: all(self.feed.statuses.get(k, 0) >= n for k, n in counts.items()), timeout)

    def request_status(self, skillset: str) -> None:
        """Ask ``skillset``'s manager to publish its status."""
        pub, payload = self._requests[skillset]
        attachment = None
        if self.style.rmw_zenoh:
            self._sequence += 1
            attachment = rmw_attachment(self._sequence, time.time_ns(), self._gid)
        pub.put(payload, attachment=attachment)

    def _ask_status(self, retry: float) -> None:
        delay = retry
        while not self._stop.is_set():
            missing = [n for n in self.feed.managers if not self.feed.has_status(n)]
            if not missing:
                return
            for name in missing:
                self.request_status(name)
            self._stop.wait(delay)
            delay = min(delay * 2, 1.0)

    def close(self) -> None:
        """Stop asking, let the worker finish what is queued, undeclare everything."""
        if self._stop.is_set():
            return
        self._stop.set()
        undeclare(self._token, self._resync, *self._subscribers)
        self._queue.put(None)
        self._worker.join(5.0)
        if self._asker is not None:
            self._asker.join(5.0)
        undeclare(*self._events.values(), *(p for p, _ in self._requests.values()))


def start_bridge(session: zenoh.Session, system: System, typemap: Mapping[str, str], **options: Any) -> Bridge:
    """Start a bridge for every manager of ``system`` on ``session``; options as :class:`Bridge`."""
    return Bridge(session, system, typemap, **options)


__all__ = ["Bridge", "default_source", "start_bridge"]
