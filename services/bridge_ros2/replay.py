"""Replay of a recorded rosbag2 file through the bridge's derivation (SPEC §1).

Reads sqlite3 and mcap bags with ``rosbags.highlevel.AnyReader``, keeps the
manager topics the system knows (by ROS topic name, e.g.
``/spot/spot_skillset_manager/spot_skillset/status``), and feeds them in time
order to the same :class:`~services.bridge_ros2.feed.Feed` as the live bridge:
as fast as possible, or paced by the recorded timestamps with ``realtime``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from rosbags.highlevel import AnyReader

from services.bridge_ros2.feed import Feed
from skinet.system import System
from skinet.wire.messages import CanonicalEvent

log = logging.getLogger("skinet.bridge_ros2")


def replay_bag(
    path: str | Path,
    system: System,
    typemap: Mapping[str, str],
    emit: Callable[[CanonicalEvent], None],
    *,
    source: str = "bridge_ros2/replay",
    realtime: bool = False,
    extra_types: Mapping[str, str] | None = None,
    hold: float = 0.5,
) -> Feed:
    """Feed every manager message of the bag at ``path`` to a new :class:`Feed`; returns it.

    Raises ``rosbags`` errors (``ReaderError`` and friends) when the bag cannot be read.
    """
    feed = Feed(system, typemap, source, extra_types, hold=hold)
    routes = feed.by_fqn()
    with AnyReader([Path(path)]) as reader:
        connections = [c for c in reader.connections if c.topic in routes]
        skipped = sorted({c.topic for c in reader.connections} - set(routes))
        if skipped:
            log.info("replay: %d topics not watched: %s", len(skipped), ", ".join(skipped))
        first: int | None = None
        origin = time.monotonic()
        for conn, timestamp, raw in reader.messages(connections=connections):
            if realtime:
                first = timestamp if first is None else first
                delay = origin + (timestamp - first) * 1e-9 - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            skillset, topic = routes[conn.topic]
            for ev in feed.feed(skillset, topic, bytes(raw)) + feed.expire():
                emit(ev)
    for ev in feed.flush():
        emit(ev)
    return feed


__all__ = ["replay_bag"]
