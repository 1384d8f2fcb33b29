"""Replay of a recorded rosbag2 file through the bridge's derivation (docs/semantics.md §1).

Reads sqlite3 and mcap bags with ``rosbags.highlevel.AnyReader``, keeps the
manager topics the system knows (by ROS topic name, e.g.
``/spot/spot_skillset_manager/spot_skillset/status``), and feeds them in time
order to the same :class:`~services.bridge_ros2.feed.Feed` as the live bridge:
as fast as possible, or paced by the recorded timestamps with ``realtime``.
SkiNet's own logs (``skinet record``: JSON Lines, or MCAP of JSON messages) are
no bags: :func:`monitor_log` recognises them, so that the bridge can point at
``skinet replay``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from services.bridge_ros2.feed import Feed
from skinet.errors import SourceError
from skinet.system.model import System
from skinet.wire.log import read_log
from skinet.wire.mcap_log import LIBRARY, MAGIC, is_mcap
from skinet.wire.messages import CanonicalEvent

log = logging.getLogger("skinet.bridge_ros2")
HEAD = 256 << 10  # bytes read to recognise a JSON Lines log


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
    from rosbags.highlevel import AnyReader

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


def monitor_log(path: str | Path) -> str | None:
    """What SkiNet log the file at ``path`` is (``"MCAP"``, ``"JSON Lines"``), or None when it is none
    (a bag, a folder, an unreadable file: the bag reader says why)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    path = Path(path)
    try:
        with path.open("rb") as f:
            if is_mcap(f.read(len(MAGIC))):
                f.seek(0)
                return "MCAP" if make_reader(f).get_header().library == LIBRARY else None
            f.seek(0)
            head = f.read(HEAD)  # a log line is a few KiB; a bag may have no line break at all
        first = next((line for line in head.splitlines() if line.strip()), b"")
        read_log([first.decode("utf-8")], str(path))
    except (OSError, UnicodeDecodeError, McapError, SourceError):
        return None
    return "JSON Lines" if first else None


__all__ = ["monitor_log", "replay_bag"]
