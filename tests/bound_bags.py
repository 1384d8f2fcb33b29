"""rosbag2 files of a bound robot, recorded from the simulated one (``ros2 bag record`` of its topics).

:class:`BagRecorder` subscribes to every topic a binding reads (action statuses,
lifecycle transition events, bound topics) as ``zenoh-bridge-ros2dds`` carries them
and keeps each CDR sample with its arrival time; :meth:`BagRecorder.write` writes
them with ``rosbags``' Writer (sqlite3 or mcap), as the recorder on a robot would.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from pathlib import Path

import zenoh
from rosbags.rosbag2 import StoragePlugin, Writer

from skinet.ros.binding import Binding
from skinet.ros.keys import KeyStyle


class BagRecorder:
    def __init__(self, session: zenoh.Session, bindings: Mapping[str, Binding], style: KeyStyle = KeyStyle()):
        self.samples: list[tuple[int, str, str, bytes]] = []  # ns, topic, type, CDR
        self.stores = {t: b.store for b in bindings.values() for t in b.topics()}
        self._lock = threading.Lock()
        self._subs = []
        for b in bindings.values():
            for topic, typename in b.topics().items():
                def on_sample(sample: zenoh.Sample, topic: str = topic, typename: str = typename) -> None:
                    with self._lock:
                        stamp = max(time.time_ns(), self.samples[-1][0] + 1 if self.samples else 0)
                        self.samples.append((stamp, topic, typename, sample.payload.to_bytes()))

                self._subs.append(session.declare_subscriber(style.name_key(topic, typename),
                                                             zenoh.handlers.Callback(on_sample, indirect=False)))

    def write(self, path: Path, plugin: StoragePlugin = StoragePlugin.SQLITE3,
              types: Mapping[str, str] | None = None) -> Path:
        """The bag at ``path``; ``types`` records some topics under another type name (a wrong bag)."""
        with self._lock:
            samples = list(self.samples)
        with Writer(path, version=9, storage_plugin=plugin) as writer:
            connections = {}
            for stamp, topic, typename, data in samples:
                if topic not in connections:
                    connections[topic] = writer.add_connection(topic, (types or {}).get(topic, typename),
                                                               typestore=self.stores[topic])
                writer.write(connections[topic], stamp, data)
        return path

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
