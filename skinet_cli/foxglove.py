"""``skinet foxglove SYSTEM``: a running system live in Foxglove (docs/foxglove.md).  Arguments only; Zenoh
and the Foxglove SDK are imported when the command runs."""

from __future__ import annotations

import argparse

HELP = "serve a running system to Foxglove (WebSocket on 127.0.0.1:8765)"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from services.foxglove.app import add_foxglove_args

    c = sub.add_parser("foxglove", help=HELP,
                       description="Serve a running system live to Foxglove over its WebSocket protocol "
                                   "(foxglove.websocket.v1): the live state, verdicts per property, unsafe "
                                   "commands with their kind and why, violations, divergences and manager "
                                   "restarts, the state-space report, the pilot's status and plan, a foxglove.Log "
                                   "line per step, warning and pilot change, and series for Plot panels. A "
                                   "read-only Zenoh observer: the router's observer role is enough. Open "
                                   "docs/foxglove-layout.json in Foxglove for the panels.")
    add_foxglove_args(c)
    c.set_defaults(func=cmd_foxglove)


def cmd_foxglove(args: argparse.Namespace) -> int:
    from services.common.cli import stop_on_signals
    from services.foxglove.app import serve

    return serve(args, stop_on_signals())
