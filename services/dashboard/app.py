"""The dashboard as a command: ``skinet dashboard SYSTEM`` and ``python -m services.dashboard``.

Opens a Zenoh session (an observer; it asks the pilot only when the page sends
a goal), serves the page, warns when no monitor of the system shows up, and
runs until ``stop`` is set.  Errors (port
in use, no router, refused login, bad system file) are raised as one-line
:class:`~skinet.errors.SkinetError` for the caller's handler.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import threading
from pathlib import Path

import zenoh

from services.common.cli import add_log_arg, setup_logging
from services.common.options import count
from services.common.zenoh_config import add_zenoh_args, client_name, config_from_args, open_session, said_at_the_end
from services.dashboard.observer import Observer, add_view_args, follow, resolve_system
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


def goal_config(args: argparse.Namespace, config: zenoh.Config) -> zenoh.Config | None:
    """The Zenoh configuration of the goal box's own login (``--goal-user``), at the router the page's
    session connects to; ``None`` without one.  :class:`SkinetError` (one line) for what cannot log in."""
    user = getattr(args, "goal_user", None)
    if not user:
        return None
    from services.common.zenoh_config import login, session_config
    from services.secrets.handout import client_config, client_files

    connect = json.loads(config.get_json("connect/endpoints") or "[]")
    if not connect:
        raise SkinetError(f"--goal-user {user} logs in to a router: give its endpoint with --connect/-e")
    folder = Path(args.goal_secrets or os.environ.get("SKINET_SECRETS")
                  or Path.home() / ".config" / "skinet" / "secrets")
    tls = [e for e in connect if e.startswith("tls/")]
    if tls:  # the router binds certificates to users: the goal login brings its own
        return zenoh.Config.from_json5(json.dumps(client_config(client_files(folder, user), tls[0])))
    password = login(argparse.Namespace(user=user, password=None, password_file=str(folder / f"{user}.password")))
    return session_config("client", connect, user=user, password=password["password"])


def serve(args: argparse.Namespace, stop: threading.Event) -> int:
    """Run the dashboard until ``stop``; returns the exit status.  Raises :class:`SkinetError`
    (one line: a bad system file or name, no router, a refused login, a port in use)."""
    setup_logging(args)
    log = logging.getLogger("skinet.dashboard")
    name, system = resolve_system(args.system)
    config = config_from_args(args)
    goals = goal_config(args, config)  # before any session: a missing secret is one line
    session = open_session(config, said_at_the_end)  # an endpoint still unreached after --wait: follow's error
    try:
        goal_session = open_session(goals) if goals is not None else None
    except SkinetError:
        session.close()
        raise
    observer = Observer(session, name, system, client=client_name(config),
                        goal_login=None if goal_session is None else (goal_session, client_name(goals)))
    dashboard = Dashboard(observer, args.host, args.port)
    try:
        dashboard.start()
    except SkinetError:
        observer.close()
        session.close()
        if goal_session is not None:
            goal_session.close()
        raise
    print(f"skinet dashboard: system {name} on {dashboard.url}"
          + (f"; its goal box sends as user {args.goal_user}" if goals is not None else ""), file=sys.stderr, flush=True)
    foxglove = None
    try:
        if args.foxglove is not None:
            from services.foxglove.app import start_foxglove

            foxglove = start_foxglove(observer, args.host, args.foxglove)
            print(f"skinet dashboard: Foxglove on {foxglove.url}", file=sys.stderr, flush=True)
        follow(observer, config, args.wait, stop, log)
    finally:
        if foxglove is not None:
            foxglove.close()
        dashboard.close()
        observer.close()
        session.close()
        if goal_session is not None:
            goal_session.close()
    return 0


