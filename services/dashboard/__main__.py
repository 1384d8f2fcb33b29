"""``python -m services.dashboard SYSTEM`` : the live web dashboard as a process (SPEC §7)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
from collections.abc import Sequence

from services.common.cli import add_log_arg, setup_logging
from services.common.zenoh_config import add_zenoh_args
from services.dashboard.app import add_dashboard_args, serve


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m services.dashboard",
        description="SkiNet Live dashboard: a web page showing a running system live (skillsets, properties, "
                    "unsafe commands with their kind, steps and witness, predictions, violations, timeline), "
                    "fed by a read-only Zenoh observer.")
    add_dashboard_args(p)
    add_log_arg(p)
    add_zenoh_args(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return serve(args, stop, logging.getLogger("skinet.dashboard"))


if __name__ == "__main__":
    sys.exit(main())
