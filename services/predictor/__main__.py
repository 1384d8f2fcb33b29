"""``python -m services.predictor``: one predictor instance in its own session (docs/semantics.md §7)."""

from __future__ import annotations

import logging
import signal
import sys
import threading

from services.common.cli import add_instance_arg, add_log_arg, one_line_errors, setup_logging
from services.common.zenoh_config import add_zenoh_args, config_from_args, open_session
from services.common.ratelimit import add_rate_args
from services.predictor.service import start_predictor
from services.common.memory import memory_size
from services.common.options import ArgumentParser, budget, count, number, seconds
from skinet.verify.explore import DEFAULT_MEMORY_LIMIT
from skinet.wire.limits import MAX_PREDICT_REQUEST

log = logging.getLogger("skinet.predictor")


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="python -m services.predictor",
        description="Answer SkiNet prediction requests on skinet/*/predict (stateless; run as many as you like).",
    )
    add_instance_arg(parser)
    parser.add_argument("--workers", type=count(), default=2,
                        help="worker processes computing forecasts (default: 2)")
    parser.add_argument("--max-pending", type=count(), default=8,
                        help="requests queued or running before 'busy' (default: 8)")
    add_rate_args(parser, check=False)
    parser.add_argument("--rate-burst", type=number(1), default=None, metavar="N",
                        help="prediction requests a client may send at once (default: one second's worth)")
    parser.add_argument("--cache", type=count(), default=4, help="systems kept in the LRU cache (default: 4)")
    parser.add_argument("--fetch-timeout", type=seconds(), default=2.0,
                        help="seconds to wait for a model bundle (default: 2)")
    parser.add_argument("--max-budget", type=budget(), default=10.0,
                        help="cap on a request's budget, seconds, from 0.05 to 86400 (default: 10)")
    parser.add_argument("--memory-limit", type=memory_size, default=DEFAULT_MEMORY_LIMIT, metavar="SIZE",
                        help="peak memory of the process, shared by the workers, e.g. 2GiB (default: 1GiB); "
                             "beyond it answers are truncated, never refused")
    parser.add_argument("--memory-mb", type=count(64), default=2048,
                        help="address-space limit of each worker process, MB (default: 2048)")
    parser.add_argument("--max-request", type=memory_size, default=MAX_PREDICT_REQUEST, metavar="SIZE",
                        help="largest request payload decoded, e.g. 64KiB (default: 64KiB; a request carries "
                             "the live marking, a few KB); a larger one is refused unread, counted and logged")
    parser.add_argument("--grace", type=seconds(), default=1.0,
                        help="seconds past a request's budget before its worker is killed (default: 1)")
    add_log_arg(parser)
    add_zenoh_args(parser)
    return parser


@one_line_errors("python -m services.predictor")
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args)
    config = config_from_args(args)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = open_session(config)  # fails e.g. with no router at the --connect endpoint yet
    predictor = start_predictor(session, args.instance, workers=args.workers, max_pending=args.max_pending,
                                cache_size=args.cache, fetch_timeout=args.fetch_timeout, max_budget=args.max_budget,
                                memory_limit=args.memory_limit, memory_mb=args.memory_mb, grace=args.grace,
                                max_request=args.max_request, rate_limit=args.rate_limit, rate_burst=args.rate_burst)
    while not stop.wait(0.2):
        pass
    # Withdraw the queryable and answer what was admitted, then retire the whole
    # session (ZENOH.md); new queries go to another instance meanwhile.
    predictor.close()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
