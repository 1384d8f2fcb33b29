"""The monitor's side of prediction: one query in flight, latest marking next (docs/semantics.md §1, §6, §7).

The event path only calls :meth:`PredictionClient.want`, which records the
marking and wakes a worker thread; the worker sends the ``get`` with a callback
and returns.  Markings wanted while a query is in flight are folded: only the
latest is sent when the query completes, unless that query just answered it.
After a query that nobody answered, the next one waits ``retry`` seconds unless
a predictor's liveliness token appears (:meth:`instance`), so a monitor without
predictor does not flood the network; while instances are known, the same marking
is asked again after that delay (a cold instance may have missed the timeout).

Load spreading and failover (docs/semantics.md §7): the predictors' liveliness tokens name
the instances (:class:`~services.monitor.pool.Pool`); each query goes to one
instance's own key, the one with the fewest outstanding queries.  There the
instance replies an empty "working" payload at once and every 0.1 s until its
answer.  An attempt is over when the instance answers, fails (``busy``, a
crash: the ``get`` ends without a reply) or stays silent for ``stall`` seconds
(frozen); then the same request goes to another instance with the exploration
budget that still fits before the query's deadline (``timeout`` after the
first attempt).  Without any token the monitor queries the shared key
``skinet/<system>/predict/<client>`` and lets the router pick (predictors that do not
advertise themselves).  Cost per attempt: O(instances) to pick one.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import zenoh

from services.monitor.pool import Pool
from skinet.system.model import Marking, System
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.convert import statuses
from skinet.wire.limits import MAX_BUDGET, MIN_BUDGET
from skinet.wire.messages import PredictReply, PredictRequest

log = logging.getLogger("skinet.monitor")


@dataclass
class PredictorStats:
    """Predict queries and their fate, for operator views."""

    sent: int = 0  # queries (one marking each), whatever the number of attempts
    answered: int = 0  # ok replies
    timed_out: int = 0  # no reply within the query timeout (error reply)
    unanswered: int = 0  # completed without any reply: no predictor reachable
    failed: int = 0  # ok=False, undecodable or for another model
    superseded: int = 0  # answered after the marking had changed
    retried: int = 0  # attempts on another instance after a crash, a freeze or a failure
    in_flight: bool = False
    last_time: float | None = None  # exploration seconds of the last answer
    last_markings: int | None = None
    last_complete: bool | None = None
    last_instance: str = ""
    instances: list[str] = field(default_factory=list)  # live predictor instances
    answers: dict[str, int] = field(default_factory=dict)  # ok replies per instance


def query_timeout(budget: float) -> float:
    """Default predict-query timeout for a request ``budget`` (seconds).

    The predictor bounds its whole answer by the budget plus a small constant
    (docs/semantics.md §6.1: deadline checked per chunk), and the first query of a system
    also waits for the model bundle (the predictor's default fetch timeout,
    2 s): a quarter of the budget and a second on top cover scheduling on a
    loaded machine, so an answer within budget is never reported as a timeout.
    """
    return 1.25 * budget + 3.0


def check_budget(budget: float, timeout: float | None = None) -> None:
    """Refuse a budget no predictor accepts, or a timeout no answer can meet (ValueError, one line).

    Below :data:`~skinet.wire.messages.MIN_BUDGET` the monitor would never query,
    and every prediction would stay stale without a word.
    """
    if not budget >= MIN_BUDGET:
        raise ValueError(f"budget {budget:g} s is below the predictor's minimum of {MIN_BUDGET:g} s: "
                         "no prediction could ever be asked for")
    if not budget <= MAX_BUDGET:
        raise ValueError(f"budget {budget:g} s is above the maximum of {MAX_BUDGET:g} s (one day)")
    if timeout is not None and not timeout > budget:
        raise ValueError(f"query timeout {timeout:g} s is not above the budget {budget:g} s: "
                         "no prediction could ever arrive in time")


Key = tuple[int, ...]
OnReply = Callable[[Key, PredictReply], None]


@dataclass
class _Attempt:
    instance: str | None  # None: the shared key
    cancel: zenoh.CancellationToken
    heard: float  # last reply of any kind (working or answer), or the send time
    replied: bool = False  # anything but "working"
    timed_out: bool = False
    done: bool = False
    returned: bool = False  # no longer counted as outstanding on its instance


@dataclass
class _Query:
    n: int
    key: Key
    marking: Marking
    deadline: float
    tried: set[str] = field(default_factory=set)
    attempt: _Attempt | None = None
    answered: bool = False
    failed: bool = False  # some attempt replied ok=False
    timed_out: bool = False
    again: bool = False  # the attempt ended without an answer: try another instance


class PredictionClient:
    """Sends PredictRequests for the wanted marking, never more than one marking at a time."""

    def __init__(self, session: zenoh.Session, system: System, digest: str, on_reply: OnReply, *,
                 budget: float = 1.0, timeout: float | None = None, retry: float = 0.5, stall: float = 0.5,
                 client: str = keys.LOCAL_CLIENT):
        check_budget(budget, timeout)
        self.session, self.system, self.digest, self.on_reply = session, system, digest, on_reply
        self.client = client  # the client chunk of the keys queried: this session's router login
        self.budget, self.timeout, self.retry = budget, timeout if timeout is not None else query_timeout(budget), retry
        self.stall = stall
        self.stats = PredictorStats()
        self.pool = Pool()
        self._cond = threading.Condition()
        self._wanted: tuple[Key, Marking] | None = None
        self._query: _Query | None = None
        self._not_before = 0.0
        self._closed = False
        self._n = 0
        self._cancels: set[zenoh.CancellationToken] = set()  # of attempts whose callbacks may still run
        self._thread = threading.Thread(target=self._run, name="skinet-monitor-predict", daemon=True)
        self._thread.start()

    def want(self, key: Key, marking: Marking) -> None:
        """Ask for a prediction of ``marking`` (cheap; called on the event path)."""
        with self._cond:
            self._wanted = (key, marking)
            self._cond.notify()

    def instance(self, token: str, alive: bool) -> None:
        """A predictor's liveliness token appeared (lifts the retry delay) or went away."""
        instance = token.rsplit("/", 1)[-1]
        with self._cond:
            if alive:
                self.pool.add(instance)
                self._not_before = 0.0
            else:
                self.pool.remove(instance)
            self._cond.notify()

    def snapshot(self) -> PredictorStats:
        with self._cond:
            return dataclasses.replace(self.stats, instances=self.pool.names(), answers=dict(self.stats.answers))

    def superseded(self) -> None:
        """Count an answer that came after the marking had changed."""
        with self._cond:
            self.stats.superseded += 1

    def close(self) -> None:
        """Stop sending and cancel the query in flight; returns once its callbacks are done."""
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join(timeout=2.0)
        with self._cond:
            cancels = list(self._cancels)
        for cancel in cancels:
            cancel.cancel()
        with self._cond:  # a callback left running at interpreter exit aborts the process
            self._cond.wait_for(lambda: not self._cancels, timeout=2.0)

    # -- worker thread ----------------------------------------------------------------

    def _run(self) -> None:
        while True:
            stalled: _Attempt | None = None
            with self._cond:
                while True:
                    if self._closed:
                        return
                    now = time.monotonic()
                    q = self._query
                    if q is None:
                        wait = self._not_before - now
                        if self._wanted is not None and wait <= 0:
                            q = self._start(now)
                            break
                        self._cond.wait(wait if self._wanted is not None else None)
                        continue
                    a = q.attempt
                    if q.answered or (a is not None and a.done and not q.again) or now >= q.deadline:
                        self._finish(q)
                        continue
                    if q.again:
                        break
                    assert a is not None
                    if a.instance is not None and not a.replied and now - a.heard >= self.stall:
                        stalled = a  # frozen: silent for several heartbeats
                        self.pool.suspect(a.instance)
                        log.warning("predictor %s silent for %.1f s: asking another instance",
                                    a.instance, now - a.heard)
                        q.again = True
                        break
                    until = q.deadline if a.instance is None or a.replied else min(q.deadline, a.heard + self.stall)
                    self._cond.wait(max(until - now, 0.001))
            if stalled is not None:
                stalled.cancel.cancel()  # its callbacks take the lock: not held here
            self._attempt(q)

    def _start(self, now: float) -> _Query:
        """A new query for the wanted marking (lock held)."""
        assert self._wanted is not None
        (key, marking), self._wanted = self._wanted, None
        self._n += 1
        self.stats.sent += 1
        self.stats.in_flight = True
        self._query = _Query(self._n, key, marking, now + self.timeout, again=True)
        return self._query

    def _finish(self, q: _Query) -> None:
        """The query is over: count its fate, pace the next one (lock held)."""
        if not q.answered:
            if not (q.timed_out or q.failed):  # those are counted per reply
                self.stats.unanswered += 1
            self._not_before = time.monotonic() + self.retry
            if self._wanted is None and self.pool:  # instances are up (maybe cold, busy): ask again
                self._wanted = (q.key, q.marking)
        elif self._wanted is not None and self._wanted[0] == q.key:
            self._wanted = None  # wanted again while in flight, and now answered
        # An attempt still open ends by itself: answered, or its get times out at the
        # deadline (cancelling here could wait for a callback that waits for this lock).
        self._query = None
        self.stats.in_flight = False

    def _attempt(self, q: _Query) -> None:
        """Send ``q`` to the least loaded untried instance, or end it when none is left."""
        with self._cond:
            if self._query is not q or self._closed:
                return
            q.again = False
            first = q.attempt is None
            instance = self.pool.pick(exclude=q.tried)
            remaining = q.deadline - time.monotonic()
            budget = self.budget if first else min(self.budget, remaining - (self.timeout - self.budget))
            if (instance is None and not (first and not self.pool)) or budget < MIN_BUDGET:  # not worth a retry
                if q.attempt is not None:
                    q.attempt.done = True  # nothing left to try: _run finishes the query
                else:
                    self._finish(q)
                self._cond.notify()
                return
            if not first:
                self.stats.retried += 1
            if instance is not None:
                q.tried.add(instance)
                self.pool.sent(instance)
            a = _Attempt(instance, zenoh.CancellationToken(), time.monotonic())
            q.attempt = a
            self._cancels.add(a.cancel)
        request = PredictRequest(system=self.system.name, digest=self.digest, seq=q.n,
                                 skillsets=statuses(self.system, q.marking), budget=budget,
                                 af=self.system.prediction.af_modes([p.name for p in self.system.properties]))
        name = self.system.name
        key = keys.predict(name, self.client) if instance is None else keys.predict_instance(name, self.client, instance)
        handler = zenoh.handlers.Callback(_bind(self._on_reply, q, a), _bind(self._on_done, q, a))
        # DROP on an instance key: a query stuck behind a dead link must not block the
        # router's other traffic (the monitor's verdicts); a lost query is a silent
        # instance, asked again elsewhere after ``stall``.
        congestion = zenoh.CongestionControl.BLOCK if instance is None else zenoh.CongestionControl.DROP
        try:
            self.session.get(key, handler, payload=encode(request), timeout=max(remaining, 0.001), express=True,
                             cancellation_token=a.cancel, congestion_control=congestion,
                             consolidation=zenoh.ConsolidationMode.NONE)
        except Exception as exc:  # session closed under us
            log.warning("predict query failed: %s", exc)
            self._on_done(q, a)

    # -- Zenoh callbacks --------------------------------------------------------------

    def _on_reply(self, q: _Query, a: _Attempt, reply: zenoh.Reply) -> None:
        if reply.ok is None:
            with self._cond:
                a.replied = a.timed_out = True
                self.stats.timed_out += 1
                q.timed_out = True
            log.warning("predict query #%d: error reply %s", q.n, _text(reply.err.payload) if reply.err else "")
            return
        payload = reply.ok.payload.to_bytes()
        if not payload:  # "working": the instance is alive
            with self._cond:
                a.heard = time.monotonic()
            return
        try:
            msg = decode(payload, PredictReply)
        except DecodeError as exc:
            msg, why = None, str(exc)
        else:
            why = "" if msg.ok and msg.seq == q.n and msg.digest == self.digest else (
                msg.error or f"reply seq {msg.seq}/digest {msg.digest[:8]} does not match query #{q.n}")
        with self._cond:
            a.replied = True
            a.heard = time.monotonic()
            self._returned(a)  # answered: no load on the instance any more, even before the get ends
            if q.answered or self._closed:
                return  # a late answer of a stalled attempt, after another one
            if why:
                self.stats.failed += 1
                q.failed = True
            else:
                assert msg is not None
                q.answered = True
                self.stats.answered += 1
                self.stats.last_instance = msg.instance
                self.stats.answers[msg.instance] = self.stats.answers.get(msg.instance, 0) + 1
                if msg.report is not None:
                    self.stats.last_time = msg.report.time
                    self.stats.last_markings = msg.report.markings
                    self.stats.last_complete = not msg.report.timeout_reached
                if a.instance is not None:
                    self.pool.answered(a.instance)
            self._cond.notify()
        if why:
            log.warning("predict query #%d failed: %s", q.n, why)
        else:
            self.on_reply(q.key, msg)  # type: ignore[arg-type]

    def _on_done(self, q: _Query, a: _Attempt) -> None:
        with self._cond:
            a.done = True
            self._returned(a)
            if q.attempt is a and not q.answered and not a.timed_out and self._query is q:
                q.again = a.instance is not None  # crashed or failed: another instance, if any
            self._cancels.discard(a.cancel)
            self._cond.notify_all()


    def _returned(self, a: _Attempt) -> None:
        if a.instance is not None and not a.returned:
            a.returned = True
            self.pool.returned(a.instance)


def _bind(fn: Callable, q: _Query, a: _Attempt) -> Callable:
    return lambda *args: fn(q, a, *args)


def _text(payload: zenoh.ZBytes) -> str:
    try:
        return payload.to_string()
    except Exception:
        return repr(payload.to_bytes())
