"""``python -m services.monitor SYSTEM.toml [zenoh flags]``: the monitor as a process (docs/semantics.md §1, §7)."""

from __future__ import annotations

import logging
import signal
import sys
import threading
from collections.abc import Sequence

from services.common.cli import add_log_arg, one_line_errors, setup_logging
from services.common.zenoh_config import add_zenoh_args, client_name, config_from_args, open_session
from services.common.ratelimit import add_rate_args
from services.monitor.incidents import add_incidents_args, start_incidents
from services.monitor.check import add_policy_arg
from services.monitor.service import start_monitor
from services.monitor.sync import add_lost_after_arg
from services.common.options import (
    ArgumentParser, add_no_properties_arg, budget, key_name, load_live_system, require_properties, seconds,
)


def build_parser() -> ArgumentParser:
    p = ArgumentParser(
        prog="python -m services.monitor",
        description="SkiNet Live monitor: follows the live marking of a system from its canonical "
                    "events, runs Algorithm 1 and publishes state, verdicts and unsafe transitions.",
    )
    p.add_argument("system", help="system file (.toml), e.g. skillsets/spot_arm.toml")
    p.add_argument("--id", dest="instance_id", type=key_name("instance id"), help="instance id in the liveliness token (default: random)")
    p.add_argument("--budget", type=budget(), default=1.0,
                   help="predictor exploration budget, seconds, from 0.05 to 86400 (default: 1)")
    p.add_argument("--query-timeout", type=seconds(),
                   help="predict query timeout, seconds (default: 1.25 x budget + 3: the predictor answers within "
                        "its budget, the first query also waits for the model bundle)")
    p.add_argument("--stall", type=seconds(), default=0.5,
                   help="seconds without a 'working' reply after which a predictor instance counts as frozen "
                        "and the query goes to another one (default: 0.5; instances reply every 0.1 s)")
    p.add_argument("--no-express", dest="express", action="store_false",
                   help="let Zenoh batch publications (higher burst throughput; default: express)")
    add_incidents_args(p)
    add_no_properties_arg(p)
    add_policy_arg(p)
    add_lost_after_arg(p)
    add_rate_args(p, predict=False)
    add_log_arg(p)
    add_zenoh_args(p)
    return p


@one_line_errors("python -m services.monitor")
def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.query_timeout is not None and args.query_timeout <= args.budget:
        parser.error(f"argument --query-timeout: {args.query_timeout:g} s is not above --budget {args.budget:g} s: "
                     "no prediction could ever arrive in time")
    setup_logging(args)
    system, warnings = load_live_system(args.system)
    require_properties(system, args.system, args.no_properties)
    config = config_from_args(args)
    log = logging.getLogger("skinet.monitor")
    for w in warnings:
        log.debug("%s", w)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = open_session(config)
    incidents = None
    try:
        incidents = start_incidents(session, system, args)
        monitor = start_monitor(session, system, instance_id=args.instance_id, budget=args.budget,
                                query_timeout=args.query_timeout, stall=args.stall, express=args.express,
                                check_policy=args.check_policy, client=client_name(config),
                                check_rate_limit=args.check_rate_limit, lost_after=args.lost_after,
                                tap=None if incidents is None else incidents.record)
        log.info("monitoring %s (model %s) as %s", system.name, monitor.digest, monitor.instance_id)
        while not stop.wait(0.5):
            pass
        monitor.close()
        c = monitor.counters
        k = monitor.check_counters
        log.info("stopped: %d received, %d applied, %d malformed, %d duplicates, %d out of order, %d lost, "
                 "%d divergences; %d unrecovered, %d jumps, %d restarts, %d resyncs, %d history; checks: %d "
                 "answered, %d errors, %d oversized, %d rate limited, %d waited (%d early, for another client's "
                 "share of the waiting slots)", c.received, c.applied,
                 c.malformed, c.duplicates, c.out_of_order, c.lost, c.divergences, c.unrecovered, c.jumps,
                 c.restarts, c.resyncs, c.history, k.answered, k.errors, k.oversized, k.rate_limited, k.waited,
                 k.made_room)
    finally:
        if incidents is not None:  # after the monitor: a pending bundle gets its last messages
            incidents.close()
        session.close()
    return 0

if __name__ == "__main__":
    sys.exit(main())
