"""``python -m services.monitor SYSTEM.toml [zenoh flags]``: the monitor as a process (SPEC §1, §7)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Sequence

import zenoh

from services.common.cli import add_log_arg, setup_logging
from services.common.zenoh_config import add_zenoh_args, config_from_args
from services.monitor.service import start_monitor
from skinet.errors import SourceError
from skinet.files import load_system


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m services.monitor",
        description="SkiNet Live monitor: follows the live marking of a system from its canonical "
                    "events, runs Algorithm 1 and publishes state, verdicts and unsafe transitions.",
    )
    p.add_argument("system", help="system file (.toml), e.g. skillsets/spot_arm.toml")
    p.add_argument("--id", dest="instance_id", help="instance id in the liveliness token (default: random)")
    p.add_argument("--budget", type=float, default=1.0, help="predictor exploration budget, seconds (default: 1)")
    p.add_argument("--query-timeout", type=float, help="predict query timeout, seconds (default: budget + 1)")
    p.add_argument("--no-express", dest="express", action="store_false",
                   help="let Zenoh batch publications (higher burst throughput; default: express)")
    add_log_arg(p)
    add_zenoh_args(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args)
    try:
        system, warnings = load_system(args.system)
    except SourceError as exc:
        print(str(exc), file=sys.stderr)
        return 1
    log = logging.getLogger("skinet.monitor")
    for w in warnings:
        log.debug("%s", w)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = zenoh.open(config_from_args(args))
    try:
        monitor = start_monitor(session, system, instance_id=args.instance_id, budget=args.budget,
                                query_timeout=args.query_timeout, express=args.express)
    except ValueError as exc:  # a bad instance id or system name for a Zenoh key
        session.close()
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        log.info("monitoring %s (model %s) as %s", system.name, monitor.digest, monitor.instance_id)
        while not stop.wait(0.5):
            pass
        monitor.close()
        c = monitor.counters
        log.info("stopped: %d received, %d applied, %d malformed, %d duplicates, %d out of order, %d lost, "
                 "%d divergences; %d unrecovered, %d jumps, %d restarts, %d resyncs", c.received, c.applied,
                 c.malformed, c.duplicates, c.out_of_order, c.lost, c.divergences, c.unrecovered, c.jumps,
                 c.restarts, c.resyncs)
    finally:
        session.close()
    return 0

if __name__ == "__main__":
    sys.exit(main())
