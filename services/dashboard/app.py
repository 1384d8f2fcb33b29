"""The dashboard as a command: ``skinet dashboard SYSTEM`` and ``python -m services.dashboard``.

Opens a Zenoh session (an observer; it asks the pilot only when the page sends
a goal), serves the page, warns when no monitor of the system shows up, and
runs until ``stop`` is set.  Errors (port
in use, no router, refused login, bad system file) are raised as one-line
:class:`~skinet.errors.SkinetError` for the caller's handler.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading

from services.common.cli import add_log_arg, setup_logging
from services.common.options import count
from services.common.zenoh_config import add_zenoh_args
from services.dashboard.observer import add_view_args, follow, observe
from services.dashboard.server import Dashboard
from skinet.errors import SkinetError


def add_dashboard_args(p: argparse.ArgumentParser) -> None:
    """The dashboard's arguments, its log level and the Zenoh flags."""
    add_view_args(p, ("SKINET_DASHBOARD_HOST", "SKINET_DASHBOARD_PORT"), 8080,
                  "system file (.toml, gives the name and the timeline's lanes) or system name")
    p.add_argument("--foxglove", type=count(0, 65535, env="SKINET_DASHBOARD_FOXGLOVE"),
                   default=os.environ.get("SKINET_DASHBOARD_FOXGLOVE") or None, metavar="PORT",
                   help="also serve the system to Foxglove (WebSocket, on --host) on this port (default: "
                        "$SKINET_DASHBOARD_FOXGLOVE, else none; see skinet foxglove)")
    g = p.add_argument_group("the goal box's own login (a secured deployment, whose observer may not send goals)")
    g.add_argument("--goal-user", default=os.environ.get("SKINET_DASHBOARD_GOAL_USER") or None, metavar="USER",
                   help="send the goal box's goals as USER, an operator-role router user, from a Zenoh session of "
                        "its own (default: $SKINET_DASHBOARD_GOAL_USER; none: the page's own login)")
    g.add_argument("--goal-secrets", default=os.environ.get("SKINET_DASHBOARD_GOAL_SECRETS") or None, metavar="DIR",
                   help="folder of USER's secrets: USER.password, and for a tls/ endpoint tls/ca.pem, tls/USER.pem, "
                        "tls/USER.key (default: $SKINET_DASHBOARD_GOAL_SECRETS, else $SKINET_SECRETS, else "
                        "~/.config/skinet/secrets)")
    add_log_arg(p)
    add_zenoh_args(p)


def serve(args: argparse.Namespace, stop: threading.Event) -> int:
    """Run the dashboard until ``stop``; returns the exit status.  Raises :class:`SkinetError`
    (one line: a bad system file or name, no router, a refused login, a port in use)."""
    setup_logging(args)
    log = logging.getLogger("skinet.dashboard")
    view = observe(args)
    observer = view.observer
    dashboard = Dashboard(observer, args.host, args.port)
    try:
        dashboard.start()
    except SkinetError:
        view.close()
        raise
    print(f"skinet dashboard: system {observer.name} on {dashboard.url}"
          + (f"; its goal box sends as user {args.goal_user}" if view.goal_session is not None else ""),
          file=sys.stderr, flush=True)
    foxglove = None
    try:
        if args.foxglove is not None:
            from services.foxglove.app import start_foxglove

            foxglove = start_foxglove(observer, args.host, args.foxglove)
            print(f"skinet dashboard: Foxglove on {foxglove.url}", file=sys.stderr, flush=True)
        follow(observer, view.config, args.wait, stop, log)
    finally:
        if foxglove is not None:
            foxglove.close()
        dashboard.close()
        view.close()
    return 0


