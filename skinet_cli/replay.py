"""``skinet replay LOG``: publish a recorded run again, for the operator views (docs/semantics.md §7).

Arguments and the command's output; the publishing is :mod:`chains.replay`.
Zenoh and the web server are imported when the command runs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from services.common.zenoh_config import add_zenoh_args
from services.common.options import count, number, seconds
from skinet.files import program

CONNECT_WAIT = 2.0  # seconds for an explicit --connect endpoint to answer before the replay gives up


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("replay", help="publish a recorded run (skinet record) again, for dashboard and watch",
                       description="Publish the monitor's messages of a recorded run (skinet record, skinet demo "
                                   "--log; JSON Lines or MCAP) again on their Zenoh keys, at the recorded pace, so "
                                   "that skinet dashboard, skinet watch and skinet record follow it as a live run "
                                   "(late joiners get the last messages). It holds a monitor's liveliness token "
                                   "(instance replay-ID) but is no monitor: the command check answers with an "
                                   "error, the log's canonical events are not published, and it refuses to start "
                                   "where a monitor of the same system is alive. For rosbag2 files of the robot's "
                                   "managers, use python -m services.bridge_ros2 SYSTEM.toml --replay BAG.")
    c.add_argument("log", metavar="LOG.jsonl|LOG.mcap", help="monitor log, JSON Lines or MCAP (skinet record)")
    c.add_argument("--speed", type=number(0), default=1.0, metavar="X",
                   help="time scale: a message recorded t seconds after the first is published at t/X; "
                        "0 = as fast as possible (default: 1, the recorded pace)")
    c.add_argument("--linger", type=seconds(zero=True), metavar="S",
                   help="after the last message, keep answering late joiners (and serving --dashboard) this "
                        "many seconds (default: until Ctrl-C or SIGTERM)")
    c.add_argument("--dashboard", type=count(0, 65535), metavar="PORT",
                   help="also serve the live web dashboard of the replay on this port (0: a free one)")
    c.add_argument("--dashboard-host", default="127.0.0.1", help="address of --dashboard (default: 127.0.0.1)")
    c.add_argument("--verify", action="store_true",
                   help="LOG is an incident bundle (skinet record --bundle): rebuild the system from its attachments "
                        "(refused when a digest does not match), re-run its events on a fresh monitor engine in this "
                        "process and compare every verdict and unsafe report step by step; prints '0 differences' "
                        "or each one, exit status 3 on a difference. Publishes nothing")
    add_zenoh_args(c)
    c.set_defaults(func=cmd_replay)


def cmd_replay(args: argparse.Namespace) -> int:
    if args.verify:
        return cmd_verify(args)
    from services.common.zenoh_config import (
        check_connected, client_name, config_from_args, open_session, said_at_the_end, wait_connected,
    )
    from chains.embedded import fix_free_ports, start_dashboard
    from services.common.cli import stop_on_signals
    from chains.replay import Replay, recording
    from skinet_cli.timeline import load_log

    rec = recording(load_log(args.log), args.log)
    config = config_from_args(args, command=True)
    listening = fix_free_ports(config) if json.loads(config.get_json("mode")) == "peer" else []
    stop = stop_on_signals()
    session = open_session(config, said_at_the_end)
    dashboard = replay = None
    try:
        if not wait_connected(session, config, CONNECT_WAIT):  # publishing to an endpoint never reached is no replay
            check_connected(session, config)
        if args.dashboard is not None:  # first: a port in use stops the replay before anything is published
            dashboard = start_dashboard(session, rec.system, args.dashboard_host, args.dashboard, client_name(config))
            print(f"dashboard on {dashboard.url}", file=sys.stderr, flush=True)
        replay = Replay(session, rec, args.log)
        endpoint = next((e for e in listening if e.startswith("tcp/")), None)
        if endpoint is not None:
            print(f"skinet replay: listening on {', '.join(listening)}; follow it with: {program.skinet()} watch {rec.system} "
                  f"-e {endpoint}", file=sys.stderr, flush=True)
        left_out = "".join(f", {n} {kind}" for kind, n in rec.left_out.items())
        print(f"skinet replay: {args.log}: system {rec.system}, {len(rec.messages)} monitor messages over "
              f"{rec.duration:.1f} s recorded, at speed {args.speed:g}"
              + ("" if rec.model else "; no model bundle in the log (views show no lanes)")
              + (f"; not published:{left_out[1:]}" if left_out else ""), file=sys.stderr, flush=True)
        started = time.monotonic()
        published = replay.play(args.speed, stop)
        print(f"skinet replay: {published} messages published in {time.monotonic() - started:.1f} s"
              + ("" if stop.is_set() else "; still answering late joiners"
                 + (" (Ctrl-C stops)" if args.linger is None else f" for {args.linger:g} s")),
              file=sys.stderr, flush=True)
        stop.wait(args.linger)
        return 0
    finally:
        if dashboard is not None:
            dashboard.close()
            dashboard.observer.close()
        if replay is not None:
            replay.close()
        session.close()


DIFFERENT = 3  # exit status of a bundle whose re-run differs


def cmd_verify(args: argparse.Namespace) -> int:
    """``skinet replay BUNDLE --verify``: see the ``--verify`` help; one-line errors for bad files."""
    from chains.bundle_verify import verify
    from skinet.errors import SkinetError
    from skinet.wire.bundle import read_bundle

    try:
        stream = open(args.log, "rb")
    except OSError as exc:
        raise SkinetError(f"{args.log}: cannot read file: {exc.strerror}") from None
    with stream:
        bundle = read_bundle(stream, args.log)
    steps, differences = verify(bundle)
    print(f"skinet replay: {args.log}: system {bundle.model.system}, {steps} steps re-run and compared",
          file=sys.stderr)
    for d in differences:
        print(d.line())
    print(f"{len(differences)} difference{'' if len(differences) == 1 else 's'}")
    return DIFFERENT if differences else 0
