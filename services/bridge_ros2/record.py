"""What the bridge reads, recorded as a rosbag2 without ROS (docs/robot.md, *Recording a bag without ROS*).

``skinet conform`` replays rosbag2 files through the bridge's derivation; a lab
without a ROS installation records one with :class:`BagRecorder`: it subscribes,
on Zenoh, to exactly the topics the bridge derives events from (each skillset
manager's ``status``, ``event_request``, ``event_response`` and
``skill/<k>/response``; each binding's action statuses, lifecycle transition
events and bound topics), in the layout's keys (``zenoh-bridge-ros2dds`` or
``rmw_zenoh``), and writes every sample as it comes: its CDR bytes unchanged, its
arrival time as the bag's timestamp, one connection per topic with the message
definitions the typestores hold (``ros2 bag info`` and ``ros2 bag play`` read
them).  Storage MCAP (default) or sqlite3, rosbag2 version 9.  Action statuses
are transient local: the recorder asks late publishers for their last one, as
the bridge does.  What a gateway never forwarded is not in the bag: the
recorder says how many messages it wrote per topic.

Callbacks run on Zenoh's own threads (the arrival order across topics is kept,
as in the bridge) and only stamp and queue each sample; one writer thread owns the
bag (sqlite3 allows no other) and writes them in that order.  Cost per sample: one
queue operation and one write of its bytes.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
import zenoh.ext as zext
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys.store import Typestore

from services.bridge_ros2.bound import BoundFeed
from services.bridge_ros2.feed import Feed
from services.common.zenoh_config import undeclare
from skinet.ros.binding import Binding
from skinet.ros.keys import KeyStyle, topic_fqn
from skinet.system.model import System

STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


@dataclass(frozen=True)
class RecordedTopic:
    """One topic the recorder writes: its ROS name, type, Zenoh key and the typestore of its definitions."""

    name: str
    typename: str
    key: str
    store: Typestore
    transient_local: bool = False


def recorded_topics(system: System, typemap: Mapping[str, str], bindings: Mapping[str, Binding],
                    style: KeyStyle = KeyStyle()) -> list[RecordedTopic]:
    """Every topic the bridge derives ``system``'s events from, in the keys of ``style``."""
    topics: list[RecordedTopic] = []
    if any(not c.binding for c in system.components):
        feed = Feed(system, typemap, "record")
        for m in feed.managers.values():
            manager = m.component.manager
            topics += [RecordedTopic(topic_fqn(manager, t.topic), t.typename, style.key(manager, t), m.store)
                       for t in m.topics]
    if bindings:
        bound = BoundFeed(system, bindings, "record", synced=True, results=False)
        for name, routes in bound.routes.items():
            route = routes[0]
            topics.append(RecordedTopic(name, route.typename, style.name_key(name, route.typename),
                                        bindings[route.skillset].store,
                                        any(r.kind == "status" for r in routes)))
    return topics


class BagRecorder:
    """Records ``topics`` from ``session`` into a new rosbag2 at ``path`` until :meth:`close`.

    ``heard_only``: a topic gets its connection with its first message, so the bag lacks the topics that
    said nothing (as a recording of whatever was published; default: every topic has one from the start).
    Raises ``OSError`` (and ``rosbags`` errors) when the bag cannot be created."""

    def __init__(self, session: zenoh.Session, path: str | Path, topics: list[RecordedTopic], *,
                 storage: str = "mcap", heard_only: bool = False):
        self.path = Path(path)
        self.counts: dict[str, int] = {t.name: 0 for t in topics}
        self._lock = threading.Lock()
        self._last = 0
        self._closed = False
        self._queue: queue.SimpleQueue[tuple[str, int, bytes] | None] = queue.SimpleQueue()
        self._opened = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._write, args=(topics, storage, heard_only), name="skinet-rosbag",
                                        daemon=True)
        self._thread.start()
        self._opened.wait()
        if self._error is not None:
            raise self._error
        self._subscribers: list[Any] = []
        for t in topics:
            handler = zenoh.handlers.Callback(self._on_sample(t.name), indirect=False)
            if t.transient_local:
                self._subscribers.append(zext.declare_advanced_subscriber(
                    session, t.key, handler, history=zext.HistoryConfig(detect_late_publishers=True)))
            else:
                self._subscribers.append(session.declare_subscriber(t.key, handler))

    def _write(self, topics: list[RecordedTopic], storage: str, heard_only: bool) -> None:
        """The writer thread: opens the bag, then writes what the callbacks queue until the end mark."""
        by_name = {t.name: t for t in topics}

        def connect(name: str) -> Any:
            return writer.add_connection(name, by_name[name].typename, typestore=by_name[name].store)

        try:
            writer = Writer(self.path, version=9, storage_plugin=STORAGES[storage])
            writer.open()
            connections = {} if heard_only else {t.name: connect(t.name) for t in topics}
        except BaseException as exc:  # reported by the constructor
            self._error = exc
            self._opened.set()
            return
        self._opened.set()
        try:
            while (item := self._queue.get()) is not None:
                name, stamp, data = item
                if name not in connections:
                    connections[name] = connect(name)
                writer.write(connections[name], stamp, data)
        finally:
            writer.close()

    def _on_sample(self, name: str):
        def on_sample(sample: zenoh.Sample) -> None:
            data = sample.payload.to_bytes()
            with self._lock:
                if self._closed:
                    return
                self._last = max(time.time_ns(), self._last + 1)  # the bag's order is the arrival order
                self._queue.put((name, self._last, data))
                self.counts[name] += 1

        return on_sample

    @property
    def messages(self) -> int:
        with self._lock:
            return sum(self.counts.values())

    def close(self) -> None:
        """Stop recording and finish the bag (every queued sample written, its metadata too)."""
        undeclare(*self._subscribers)
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._queue.put(None)
        self._thread.join()


__all__ = ["STORAGES", "BagRecorder", "RecordedTopic", "recorded_topics"]
