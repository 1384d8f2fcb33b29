"""The Foxglove connection as a command: ``skinet foxglove SYSTEM`` and ``python -m services.foxglove``.

Opens a Zenoh session (a read-only observer), serves the system's channels over
the Foxglove WebSocket protocol (:class:`~services.foxglove.server.FoxgloveView`),
warns when no monitor of the system shows up, and runs until ``stop`` is set.
Errors (port in use, no router, refused login, bad system file) are raised as
one-line :class:`~skinet.errors.SkinetError` for the caller's handler.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading

from services.common.cli import add_log_arg, setup_logging
from services.common.zenoh_config import add_zenoh_args
from services.dashboard.observer import Observer, add_view_args, follow, observe
from skinet.errors import SkinetError

DEFAULT_PORT = 8765  # Foxglove's usual WebSocket port


def add_foxglove_args(p: argparse.ArgumentParser) -> None:
    """The command's arguments, its log level and the Zenoh flags."""
    add_view_args(p, ("SKINET_FOXGLOVE_HOST", "SKINET_FOXGLOVE_PORT"), DEFAULT_PORT, "system file (.toml) or system name")
    add_log_arg(p)
    add_zenoh_args(p)


def start_foxglove(observer: Observer, host: str, port: int):  # -> FoxgloveView
    """A :class:`~services.foxglove.server.FoxgloveView` of ``observer`` (the SDK imported only here)."""
    from services.foxglove.server import FoxgloveView

    return FoxgloveView(observer, host, port)


def serve(args: argparse.Namespace, stop: threading.Event) -> int:
    """Serve until ``stop``; returns the exit status."""
    setup_logging(args)
    log = logging.getLogger("skinet.foxglove")
    view = observe(args, feed=True)  # the monitor's results in rounds: the robot's router sends one message a round
    observer = view.observer
    try:
        foxglove = start_foxglove(observer, args.host, args.port)
    except SkinetError:
        view.close()
        raise
    feed = None
    if getattr(args, "feed", None) is not None:
        from services.foxglove.feed import PipeReader

        feed = PipeReader(args.feed, observer, stop)  # the end of the pipe ends the view
    print(f"skinet foxglove: system {observer.name} on {foxglove.url} (Foxglove: Open connection, Foxglove "
          "WebSocket; layout docs/foxglove-layout.json)", file=sys.stderr, flush=True)
    try:
        follow(observer, view.config, args.wait, stop, log)
    finally:
        if feed is not None:
            feed.close()
        foxglove.close()
        view.close()
    return 0
