"""Per-client request budgets a client cannot dodge by renaming itself (issues 14 and 31; docs/semantics.md §7).

The predictor and the monitor's command check name the querier by the client chunk
of the key it queried (:func:`skinet.wire.keys.client_of`); behind the shipped
router that chunk is the querier's login, which the access control checks
(``docker/zenoh/router.json5``, docs/deployment.md "Rate limits per client").  Each client may send ``rate``
requests per second on average and ``burst`` at once; a request over its budget is refused at once
(the caller answers "rate limited") instead of queueing behind the others, so a
flooding client costs the service one cheap refusal per request while everybody
else keeps their own budget.

Without the router's access control (``skinet run``'s embedded peer) the chunk is the
client's own choice, and a client asking under a new name each time would get a full
bucket each time.  Two buckets shared by all clients close that door:

- *new names*: a name without a bucket takes a token from a bucket of ``rate`` new
  names per second (burst ``burst``), so renaming gains a client no more than one more
  client's budget;
- *total* (optional): every admitted request also takes a token from a bucket of
  ``total`` requests per second over all clients together, which bounds what the
  service spends on requests whatever the names (it protects the work beside it,
  such as the monitor's event path).

At most ``max_clients`` buckets are kept.  When a new name comes and the table is full,
the least recently used bucket is dropped only if it has filled up again (an idle
client: forgetting it loses nothing); otherwise the new name is refused, so a flood of
names can neither push a busy client out nor buy itself fresh buckets.

Cost: O(1) time per request under one lock; O(``max_clients``) memory.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable

from services.common.options import number

MAX_CLIENTS = 1024
PREDICT_RATE_LIMIT = 20.0  # default prediction requests/s per client (a monitor asks one marking at a time)
CHECK_RATE_LIMIT = 20.0  # default check requests/s per client (an operator asks before a command)
CHECK_TOTAL_FACTOR = 5.0  # the monitor's check admits at most this many clients' worth of requests/s in all

OK, CLIENT, NEW, TOTAL = "ok", "client", "new", "total"  # what :meth:`RateLimiter.take` answers


class _Bucket:
    """One token bucket (not thread-safe: its owner holds the lock)."""

    __slots__ = ("rate", "burst", "tokens", "at")

    def __init__(self, rate: float, burst: float, now: float):
        self.rate, self.burst, self.tokens, self.at = rate, burst, burst, now

    def level(self, now: float) -> float:
        self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        self.at = now
        return self.tokens


class RateLimiter:
    """Token buckets per client, for new names and (optionally) for all clients together; thread-safe,
    O(1) per request."""

    def __init__(self, rate: float, burst: float | None = None, *, total: float | None = None,
                 max_clients: int = MAX_CLIENTS, clock: Callable[[], float] = time.monotonic):
        """``rate``: requests per second per client, 0 or less: no limit at all; ``burst``:
        requests at once (default: one second's worth, at least 1); ``total``: requests per
        second over all clients together (burst one second's worth), None or 0: none."""
        self.rate = rate
        self.burst = burst if burst is not None else max(1.0, rate)
        self.total = total if total is not None and total > 0 and rate > 0 else None
        self.max_clients = max_clients
        self._clock = clock
        now = clock()
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()  # client -> (tokens, at)
        self._new = _Bucket(self.rate, self.burst, now)
        self._all = _Bucket(self.total, max(1.0, self.total), now) if self.total else None
        self._lock = threading.Lock()

    @property
    def enabled(self) -> bool:
        return self.rate > 0

    def allow(self, client: str) -> bool:
        """Take one request from ``client``'s budget; False when it has none left."""
        return self.take(client) == OK

    def take(self, client: str) -> str:
        """Take one request from ``client``'s budget: ``OK``, or which budget refused it (``CLIENT``: its
        own, ``NEW``: the new names', ``TOTAL``: all clients'); a refusal takes nothing."""
        if self.rate <= 0:
            return OK
        now = self._clock()
        with self._lock:
            known = self._buckets.pop(client, None)
            if known is None:
                tokens = self.burst
                if self._new.level(now) < 1.0:
                    return NEW
                if len(self._buckets) >= self.max_clients and not self._drop_idle(now):
                    return NEW
            else:
                tokens = min(self.burst, known[0] + (now - known[1]) * self.rate)
            verdict = OK if tokens >= 1.0 else CLIENT
            if verdict == OK and self._all is not None and self._all.level(now) < 1.0:
                verdict = TOTAL
            if verdict == OK:
                tokens -= 1.0
                if self._all is not None:
                    self._all.tokens -= 1.0
                if known is None:
                    self._new.tokens -= 1.0
            if known is not None or verdict == OK:
                self._buckets[client] = (tokens, now)  # most recently used last
            return verdict

    def _drop_idle(self, now: float) -> bool:
        """Drop the least recently used bucket if it has filled up again (lock held)."""
        oldest, (tokens, at) = next(iter(self._buckets.items()))
        if tokens + (now - at) * self.rate < self.burst:
            return False
        del self._buckets[oldest]
        return True

    def tracked(self) -> int:
        """Clients with a bucket now."""
        with self._lock:
            return len(self._buckets)

    def refusal(self, client: str, why: str = CLIENT) -> str:
        """The one-line error of a request refused by ``why`` (see :meth:`take`)."""
        if why == NEW:
            return (f"rate limited: too many new clients (more than {self.rate:g} new names/s, "
                    f"{self.max_clients} clients at most); ask again under a name already used")
        if why == TOTAL and self.total is not None:
            return f"rate limited: all clients together exceed {self.total:g} requests/s"
        return f"rate limited: client '{client}' exceeds {self.rate:g} requests/s (burst {self.burst:g})"


def add_rate_args(parser: argparse.ArgumentParser, *, predict: bool = True, check: bool = True) -> None:
    """``--rate-limit`` (the predictor's, ``$SKINET_RATE_LIMIT``) and ``--check-rate-limit``
    (the monitor's command check, ``$SKINET_CHECK_RATE_LIMIT``): requests per second per client."""
    what = (" per client (the key's client chunk: its router login), and as many new client names per second; "
            "beyond it 'rate limited' at once; 0: no limit")
    if predict:
        parser.add_argument("--rate-limit", type=number(0, "SKINET_RATE_LIMIT"), metavar="PER_S",
                            default=os.environ.get("SKINET_RATE_LIMIT", PREDICT_RATE_LIMIT),
                            help=f"prediction requests per second{what} "
                                 f"(default: $SKINET_RATE_LIMIT or {PREDICT_RATE_LIMIT:g})")
    if check:
        parser.add_argument("--check-rate-limit", type=number(0, "SKINET_CHECK_RATE_LIMIT"), metavar="PER_S",
                            default=os.environ.get("SKINET_CHECK_RATE_LIMIT", CHECK_RATE_LIMIT),
                            help=f"command check requests per second{what}; 5 times as many from all clients "
                                 f"together "
                                 f"(default: $SKINET_CHECK_RATE_LIMIT or {CHECK_RATE_LIMIT:g})")
