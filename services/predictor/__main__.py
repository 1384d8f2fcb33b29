"""``python -m services.predictor``: one predictor instance in its own session (SPEC §7)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

import zenoh

from services.common.cli import add_instance_arg, add_log_arg, setup_logging
from services.common.zenoh_config import add_zenoh_args, config_from_args
from services.predictor.service import start_predictor
from skinet.wire.keys import check_chunk

log = logging.getLogger("skinet.predictor")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m services.predictor",
        description="Answer SkiNet prediction requests on skinet/*/predict (stateless; run as many as you like).",
    )
    add_instance_arg(parser)
    parser.add_argument("--workers", type=int, default=2,
                        help="worker processes computing forecasts (default: 2)")
    parser.add_argument("--max-pending", type=int, default=8,
                        help="requests queued or running before 'busy' (default: 8)")
    parser.add_argument("--cache", type=int, default=4, help="systems kept in the LRU cache (default: 4)")
    parser.add_argument("--fetch-timeout", type=float, default=2.0,
                        help="seconds to wait for a model bundle (default: 2)")
    parser.add_argument("--max-budget", type=float, default=10.0,
                        help="cap on a request's budget, seconds (default: 10)")
    parser.add_argument("--memory-mb", type=int, default=2048,
                        help="address-space limit of each worker process, MB (default: 2048)")
    parser.add_argument("--grace", type=float, default=1.0,
                        help="seconds past a request's budget before its worker is killed (default: 1)")
    add_log_arg(parser)
    add_zenoh_args(parser)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging(args)
    try:
        check_chunk(args.instance, "instance id")
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        session = zenoh.open(config_from_args(args))
    except zenoh.ZError as exc:  # e.g. no router at the --connect endpoint yet
        log.error("cannot open the Zenoh session: %s", str(exc).split("  at ")[0])
        return 1
    predictor = start_predictor(session, args.instance, workers=args.workers, max_pending=args.max_pending,
                                cache_size=args.cache, fetch_timeout=args.fetch_timeout, max_budget=args.max_budget,
                                memory_mb=args.memory_mb, grace=args.grace)
    while not stop.wait(0.2):
        pass
    # Withdraw the queryable and answer what was admitted, then retire the whole
    # session (ZENOH.md); new queries go to another instance meanwhile.
    predictor.close()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
