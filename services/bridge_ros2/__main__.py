"""``python -m services.bridge_ros2 SYSTEM.toml``: canonical events from skillset managers (docs/semantics.md §1, §7)
and from skillsets bound to plain ROS 2 action servers, lifecycle nodes and topics (docs/semantics.md §9).

Live (default): subscribes to the managers' topics and the bound interfaces on Zenoh.  ``--replay BAG``:
reads a rosbag2 file (sqlite3 or mcap) instead, as fast as possible or with
``--realtime``, publishes its events and exits.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from pathlib import Path

import zenoh

from services.bridge_ros2.bound import replay_bags
from services.bridge_ros2.bound_live import start_bound_bridge
from services.bridge_ros2.replay import monitor_log, replay_bag
from services.bridge_ros2.service import add_status_poll_args, default_source, start_bridge
from services.bridge_ros2.worker import Worker
from services.common.cli import (
    add_instance_arg, add_log_arg, add_ros_key_args, key_style, one_line_errors, setup_logging,
)
from services.common.events import event_publisher
from services.common.zenoh_config import add_zenoh_args, config_from_args, open_session
from services.common.options import ArgumentParser, load_live_system, seconds
from skinet.errors import SkinetError, SourceError
from skinet.files import program
from skinet.system.load import load_bindings, load_typemap
from skinet.wire import keys
from skinet.wire.codec import encode

log = logging.getLogger("skinet.bridge_ros2")


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="python -m services.bridge_ros2",
        description="Turn what skillset managers publish, or what the action servers, lifecycle nodes and topics "
                    "of a bound skillset show (ROS 2 on Zenoh, or a rosbag2 file), into canonical events on "
                    "skinet/<system>/events/<skillset>.",
    )
    parser.add_argument("system", help="system TOML file ([system] types names the type map)")
    add_ros_key_args(parser)
    add_instance_arg(parser)
    parser.add_argument("--source", default=None, help="source name in the events (default: bridge_ros2/INSTANCE)")
    parser.add_argument("--replay", metavar="BAG", help="replay a rosbag2 file (directory or .db3/.mcap) and exit")
    parser.add_argument("--realtime", action="store_true", help="with --replay: keep the recorded timing")
    parser.add_argument("--hold", type=seconds(zero=True), default=0.5,
                        help="seconds a status may wait for a response it overtook (each topic has its own route "
                             "through a gateway); 0 derives every status at once (default: 0.5)")
    parser.add_argument("--settle", type=seconds(zero=True), default=0.5,
                        help="bound skillsets: seconds after an action server appears before its empty status cache "
                             "is read as 'no goal yet' (default: 0.5)")
    add_status_poll_args(parser)
    add_log_arg(parser)
    add_zenoh_args(parser)
    return parser


@one_line_errors("python -m services.bridge_ros2")
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args)
    system, _ = load_live_system(args.system)
    typemap = load_typemap(args.system)
    bindings, warnings = load_bindings(system)
    for w in warnings:
        log.warning("%s", w)
    if args.replay and not Path(args.replay).exists():
        raise SourceError.at(args.replay, None, "cannot read file: No such file or directory")
    kind = monitor_log(args.replay) if args.replay else None
    if kind is not None:
        raise SourceError.at(args.replay, None, f"a SkiNet monitor log ({kind}, skinet record), not a rosbag2 "
                                                f"file of the managers: replay it with '{program.skinet()} replay {args.replay}'")
    source = args.source or default_source(args.instance)
    session = open_session(config_from_args(args))
    try:
        if args.replay:
            return _replay(session, system, typemap, bindings, args, source)
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        style = key_style(args)
        bridge = None
        managed = [c.name for c in system.components if not c.binding]
        # One derivation thread, epoch and heartbeat for both kinds: their events leave in arrival order.
        worker = Worker()
        if managed:
            bridge = start_bridge(session, system, typemap, source=source, instance_id=args.instance, hold=args.hold,
                                  style=style, worker=worker, poll=args.status_poll,
                                  silent_after=args.silent_after)  # errors: one line
            log.info("bridging the managers of %s (%s) as %s", system.name, ", ".join(managed), args.instance)
        bound = start_bound_bridge(session, system, bindings, source=source, instance_id=args.instance,
                                   hold=args.hold, settle=args.settle, style=style, worker=worker) if bindings else None
        while not stop.wait(0.5):
            pass
        if bound is not None:
            bound.close()
        if bridge is not None:
            bridge.close()
            c = bridge.counters
            log.info("stopped: %d messages, %d events (%d unnamed), %d malformed, %d statuses not matching the "
                     "model, %d manager restarts, %d resyncs after a cut link", c.messages, c.events, c.unexplained,
                     c.malformed, c.mismatched, c.restarts, c.resyncs)
        worker.close()
        if bound is not None:
            _log_bound(bound.counters)
        return 0
    finally:
        session.close()


def _log_bound(c) -> None:  # type: ignore[no-untyped-def]
    bad = ", ".join(f"{n} {kind}" for kind, n in sorted(c.bad.items())) or "no other bad input"
    log.info("bound skillsets: %d messages, %d events, %d model divergences, %d malformed, %d resyncs after a gap, "
             "%s", c.messages, c.events, c.drifts, c.malformed, c.resyncs, bad)


def _replay(session: zenoh.Session, system, typemap, bindings, args: argparse.Namespace, source: str) -> int:
    publishers = {c.name: event_publisher(session, keys.events(system.name, c.name)) for c in system.components}
    if bindings:
        try:
            done = replay_bags(args.replay, system, typemap, bindings,
                               lambda ev: publishers[ev.skillset].put(encode(ev)), source=source,
                               realtime=args.realtime, hold=args.hold)
        except SkinetError:
            raise
        except Exception as exc:  # rosbags reader errors: not a bag, missing file, unknown storage
            raise SourceError.at(args.replay, None, f"cannot replay: {exc}") from None
        if done.bound is not None:
            _log_bound(done.bound.counters)
        return 0
    try:
        feed = replay_bag(args.replay, system, typemap, lambda ev: publishers[ev.skillset].put(encode(ev)),
                          source=source, realtime=args.realtime, hold=args.hold)
    except SkinetError:
        raise
    except Exception as exc:  # rosbags reader errors: not a bag, missing file, unknown storage
        raise SourceError.at(args.replay, None, f"cannot replay: {exc}") from None
    c = feed.counters
    log.info("replayed %s: %d messages, %d events (%d unnamed), %d malformed",
             args.replay, c.messages, c.events, c.unexplained, c.malformed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
