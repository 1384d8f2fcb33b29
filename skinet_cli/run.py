"""``skinet run`` and ``skinet router``: arguments only; Zenoh is imported when they run (docs/semantics.md §7)."""

from __future__ import annotations

import argparse
import os

from services.common.cli import add_ros_key_args
from services.common.ratelimit import add_rate_args
from services.common.zenoh_config import add_login_args
from services.monitor.check import add_policy_arg
from services.monitor.sync import add_lost_after_arg
from services.common.memory import TRUNCATED, add_memory_arg
from services.common.options import (
    add_no_properties_arg, add_outcome_timeout_arg, add_self_ending_args, budget, count, seconds,
)


def _zenoh_args(c: argparse.ArgumentParser, listen_help: str) -> None:
    c.add_argument("--listen", "-l", action="append", help=listen_help)
    c.add_argument("--connect", "-e", action="append", help="endpoint to connect to (repeatable)")
    c.add_argument("--zenoh-config", default=os.environ.get("SKINET_ZENOH_CONFIG"), help="JSON5 Zenoh configuration file")
    c.add_argument("--multicast-scouting", action="store_true",
                   help="join multicast scouting to find peers on the LAN (default: off)")
    c.add_argument("--no-multicast-scouting", action="store_true", help="the default; accepted for old scripts")
    add_login_args(c)


def add_commands(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("run", help="monitor, predictor and pilot in one process with a live operator view (docs/semantics.md §7, §8)")
    c.add_argument("system", help="system file (.toml), e.g. skillsets/spot_arm.toml")
    c.add_argument("--once", action="store_true", help="print one view (after the first prediction) and exit")
    c.add_argument("--duration", type=seconds(), help="stop after this many seconds")
    c.add_argument("--budget", type=budget(), default=1.0,
                   help="prediction budget in seconds, from 0.05 to 86400 (default: 1)")
    c.add_argument("--dashboard", type=count(0, 65535), metavar="PORT",
                   help="also serve the live web dashboard on this port (0: a free one; see skinet dashboard)")
    c.add_argument("--dashboard-host", default="127.0.0.1", help="address of --dashboard (default: 127.0.0.1)")
    c.add_argument("--foxglove", type=count(0, 65535), metavar="PORT",
                   help="also serve the system to Foxglove (WebSocket) on this port (0: a free one; see skinet "
                        "foxglove): a process of its own, fed the monitor's results through a pipe")
    c.add_argument("--foxglove-host", default="127.0.0.1", help="address of --foxglove (default: 127.0.0.1)")
    from services.monitor.incidents import add_incidents_args

    add_incidents_args(c)
    c.add_argument("--no-pilot", action="store_true",
                   help="do not start the pilot (docs/semantics.md §8: goals on skinet/<system>/pilot/goal/<client>, guided or "
                        "driven with the strict check; see docs/pilot.md)")
    c.add_argument("--simulate", action="store_true",
                   help="also run a simulated robot of the system on this session, with its bridge: skillset "
                        "managers (or the bound action servers, lifecycle nodes and topics) whose skills end by "
                        "themselves, for skinet goal --drive to drive (docs/pilot.md, Try the pilot in one command)")
    add_self_ending_args(c, "--simulate")
    add_outcome_timeout_arg(c)
    add_no_properties_arg(c)
    add_policy_arg(c)
    add_lost_after_arg(c)
    add_rate_args(c)
    add_memory_arg(c, f"{TRUNCATED}; the embedded pilot's plans are then unknown, and a goal is rejected with why")
    ros = c.add_argument_group("the robot's ROS 2 keys (the pilot's commands, the printed bridge command)")
    add_ros_key_args(ros)
    _zenoh_args(c, "endpoint on which a bridge, watch, dashboard or check in another process can connect "
                   "(default: tcp/127.0.0.1 with a free port, this host only; printed at start)")
    c.add_argument("--mode", "-m", choices=("peer", "client"),
                   help="peer: others connect to --listen (the default); client: run behind a router (--connect) "
                        "with a login (--user), the default when both are given")
    c.set_defaults(func=cmd_run)

    c = sub.add_parser("router", help="run a Zenoh router (the Python wheel in router mode) until interrupted")
    _zenoh_args(c, "endpoint to listen on (repeatable; default: tcp/127.0.0.1:7447, this host only)")
    c.add_argument("--secrets", default=os.environ.get("SKINET_SECRETS"),
                   help="folder of users.txt and <user>.password, made at first start when missing "
                        "(default: $SKINET_SECRETS or ~/.config/skinet/secrets)")
    c.add_argument("--handed", default=os.environ.get("SKINET_HANDED_SECRETS") or None, metavar="DIR",
                   help="copy the files of DIR (the router's hand-out of the compose job secrets, mounted read-only) "
                        "into --secrets at start (default: $SKINET_HANDED_SECRETS)")
    c.add_argument("--no-auth", action="store_true",
                   help="accept sessions without user/password (tests on a closed machine only)")
    c.add_argument("--robots", default=os.environ.get("SKINET_FLEET_ROBOTS"), metavar="ENDPOINTS",
                   help="be a fleet's hub: link to these robot routers (tls/HOST:PORT, comma-separated) over "
                        "mutual TLS as user hub (default: $SKINET_FLEET_ROBOTS; docs/deployment.md)")
    c.set_defaults(func=cmd_router)

    c = sub.add_parser("fleet", help="link robots' routers to a hub over mutual TLS: exchange the trust files")
    c.add_argument("--secrets", default=os.environ.get("SKINET_SECRETS"),
                   help="the router's secrets folder (default: $SKINET_SECRETS or ~/.config/skinet/secrets)")
    fleet = c.add_subparsers(dest="fleet_command", required=True, metavar="COMMAND")
    fleet.add_parser("invite", help="on the hub: print the invitation every robot joins with (fleet CA, hub password)")
    fleet.add_parser("join", help="on a robot: read the hub's invitation on stdin, keep it for the router's next "
                                  "start, print the robot's CA for `skinet fleet add`")
    add = fleet.add_parser("add", help="on the hub: read a robot's CA on stdin and trust it for the link to HOST")
    add.add_argument("host", metavar="HOST", help="the host of the robot's endpoint in SKINET_FLEET_ROBOTS")
    c.set_defaults(func=cmd_fleet)


def cmd_run(args: argparse.Namespace) -> int:
    from chains.embedded import run

    return run(args)


def cmd_router(args: argparse.Namespace) -> int:
    from chains.embedded import router

    return router(args)


def cmd_fleet(args: argparse.Namespace) -> int:
    """``skinet fleet invite|join|add``: the files a hub and its robots exchange (docs/deployment.md)."""
    import sys
    from pathlib import Path

    from services.common.security import add_robot, check_robot_name, fleet_invitation, join_fleet

    folder = Path(args.secrets or Path.home() / ".config" / "skinet" / "secrets")
    if args.fleet_command == "invite":
        print(fleet_invitation(folder))
    elif args.fleet_command == "join":
        sys.stdout.write(join_fleet(folder, sys.stdin.read()))
        print("skinet fleet: joined; restart this robot's router to trust the hub", file=sys.stderr)
    else:
        check_robot_name(args.host)  # before waiting on standard input
        path = add_robot(folder, args.host, sys.stdin.read())
        print(f"skinet fleet: {path} written; restart the hub to link {args.host}", file=sys.stderr)
    return 0
