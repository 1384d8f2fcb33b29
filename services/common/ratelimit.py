"""Per-client request budgets: a token bucket per client, LRU-bounded (issue 14; SPEC §7).

The predictor and the monitor's command check name the querier by the client chunk
of the key it queried (:func:`skinet.wire.keys.client_of`); behind the shipped
router that chunk is the querier's login, which the access control checks
(``docker/zenoh/router.json5``).  Each client may send ``rate`` requests per second
on average and ``burst`` at once; a request over its budget is refused at once
(the caller answers "rate limited") instead of queueing behind the others, so a
flooding client costs the service one cheap refusal per request while everybody
else keeps their own budget.

At most ``max_clients`` buckets are kept, the least recently used dropped first: a
dropped client comes back with a full bucket, which only matters when more than
``max_clients`` distinct clients are active (never behind the router, whose users
are listed; without access control the chunk is anybody's choice anyway).
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable

from skinet_cli.options import number

MAX_CLIENTS = 1024
PREDICT_RATE_LIMIT = 20.0  # default prediction requests/s per client (a monitor asks one marking at a time)
CHECK_RATE_LIMIT = 20.0  # default check requests/s per client (an operator asks before a command)


class RateLimiter:
    """Token buckets per client; thread-safe, O(1) per request."""

    def __init__(self, rate: float, burst: float | None = None, *, max_clients: int = MAX_CLIENTS,
                 clock: Callable[[], float] = time.monotonic):
        """``rate``: requests per second per client, 0 or less: no limit; ``burst``:
        requests at once (default: one second's worth, at least 1)."""
        self.rate = rate
        self.burst = burst if burst is not None else max(1.0, rate)
        self.max_clients = max_clients
        self._clock = clock
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()  # client -> (tokens, at)
        self._lock = threading.Lock()

    @property
    def enabled(self) -> bool:
        return self.rate > 0

    def allow(self, client: str) -> bool:
        """Take one request from ``client``'s budget; False when it has none left."""
        if self.rate <= 0:
            return True
        now = self._clock()
        with self._lock:
            tokens, at = self._buckets.pop(client, (self.burst, now))
            tokens = min(self.burst, tokens + (now - at) * self.rate)
            allowed = tokens >= 1.0
            if allowed:
                tokens -= 1.0
            self._buckets[client] = (tokens, now)  # most recently used last
            if len(self._buckets) > self.max_clients:
                self._buckets.popitem(last=False)
            return allowed

    def tracked(self) -> int:
        """Clients with a bucket now."""
        with self._lock:
            return len(self._buckets)

    def refusal(self, client: str) -> str:
        """The one-line error of a refused request."""
        return f"rate limited: client '{client}' exceeds {self.rate:g} requests/s (burst {self.burst:g})"


def add_rate_args(parser: argparse.ArgumentParser, *, predict: bool = True, check: bool = True) -> None:
    """``--rate-limit`` (the predictor's, ``$SKINET_RATE_LIMIT``) and ``--check-rate-limit``
    (the monitor's command check, ``$SKINET_CHECK_RATE_LIMIT``): requests per second per client."""
    what = " per client (the key's client chunk: its router login); beyond it 'rate limited' at once; 0: no limit"
    if predict:
        parser.add_argument("--rate-limit", type=number(0, "SKINET_RATE_LIMIT"), metavar="PER_S",
                            default=os.environ.get("SKINET_RATE_LIMIT", PREDICT_RATE_LIMIT),
                            help=f"prediction requests per second{what} "
                                 f"(default: $SKINET_RATE_LIMIT or {PREDICT_RATE_LIMIT:g})")
    if check:
        parser.add_argument("--check-rate-limit", type=number(0, "SKINET_CHECK_RATE_LIMIT"), metavar="PER_S",
                            default=os.environ.get("SKINET_CHECK_RATE_LIMIT", CHECK_RATE_LIMIT),
                            help=f"command check requests per second{what} "
                                 f"(default: $SKINET_CHECK_RATE_LIMIT or {CHECK_RATE_LIMIT:g})")
