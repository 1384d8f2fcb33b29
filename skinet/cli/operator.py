"""``skinet dashboard``, ``skinet watch`` and ``skinet check``: operator views of any running
deployment, as read-only Zenoh observers (SPEC §7).  Arguments only; Zenoh and the web
server are imported when a command runs."""

from __future__ import annotations

import argparse
import threading

from services.common.zenoh_config import add_zenoh_args


def add_parsers(sub: argparse._SubParsersAction) -> None:
    from services.dashboard.app import add_dashboard_args

    c = sub.add_parser("dashboard", help="live web dashboard of a running system (served on 127.0.0.1:8080)",
                       description="Serve a live web page of a running system: skillsets, properties, unsafe "
                                   "commands with kind, steps and witness, predictions, state space, violations "
                                   "and a timeline. Read-only: it observes the monitor's messages on Zenoh.")
    add_dashboard_args(c)
    add_zenoh_args(c)
    c.set_defaults(func=cmd_dashboard)


def cmd_dashboard(args: argparse.Namespace) -> int:
    import logging

    from services.dashboard.app import serve
    from services.embedded import stop_on_signals

    logging.basicConfig(level="INFO", format="skinet dashboard: %(message)s")
    return serve(args, stop_on_signals(), logging.getLogger("skinet.dashboard"))
