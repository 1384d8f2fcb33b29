"""The monitor's side of prediction: one query in flight, latest marking next (SPEC §1, §6).

The event path only calls :meth:`PredictionClient.want`, which records the
marking and wakes a worker thread; the worker sends the ``get`` with a callback
and returns.  Markings wanted while a query is in flight are folded: only the
latest is sent when the query completes, unless that query just answered it.
After a query that nobody answered, the next one waits ``retry`` seconds unless
a predictor's liveliness token appears (:meth:`poke`), so a monitor without
predictor does not flood the network.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from skinet.system import Marking, System
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.convert import statuses
from skinet.wire.messages import PredictReply, PredictRequest

log = logging.getLogger("skinet.monitor")


@dataclass
class PredictorStats:
    """Predict queries and their fate, for operator views."""

    sent: int = 0
    answered: int = 0  # ok replies
    timed_out: int = 0  # no reply within the query timeout (error reply)
    unanswered: int = 0  # completed without any reply: no predictor reachable
    failed: int = 0  # ok=False, undecodable or for another model
    superseded: int = 0  # answered after the marking had changed
    in_flight: bool = False
    last_time: float | None = None  # exploration seconds of the last answer
    last_markings: int | None = None
    last_complete: bool | None = None
    last_instance: str = ""


Key = tuple[int, ...]
OnReply = Callable[[Key, PredictReply], None]


class PredictionClient:
    """Sends PredictRequests for the wanted marking, never more than one at a time."""

    def __init__(self, session: zenoh.Session, system: System, digest: str, on_reply: OnReply, *,
                 budget: float = 1.0, timeout: float | None = None, retry: float = 0.5):
        self.session, self.system, self.digest, self.on_reply = session, system, digest, on_reply
        self.budget, self.timeout, self.retry = budget, timeout if timeout is not None else budget + 1.0, retry
        self.stats = PredictorStats()
        self._cond = threading.Condition()
        self._wanted: tuple[Key, Marking] | None = None
        self._in_flight: Key | None = None
        self._answered = self._ok = False
        self._not_before = 0.0
        self._closed = False
        self._idle = False  # the worker sleeps until something is wanted
        self._cancel = zenoh.CancellationToken()  # finishes the query in flight on close
        self._thread = threading.Thread(target=self._run, name="skinet-monitor-predict", daemon=True)
        self._thread.start()

    def want(self, key: Key, marking: Marking) -> None:
        """Ask for a prediction of ``marking`` (cheap; called on the event path)."""
        with self._cond:
            self._wanted = (key, marking)
            if self._idle:  # otherwise the query's end or the retry timer wakes the worker
                self._cond.notify()

    def poke(self) -> None:
        """A predictor appeared: lift the retry delay."""
        with self._cond:
            self._not_before = 0.0
            self._cond.notify()

    def snapshot(self) -> PredictorStats:
        with self._cond:
            return dataclasses.replace(self.stats)

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
        self._cancel.cancel()
        with self._cond:  # a callback left running at interpreter exit aborts the process
            self._cond.wait_for(lambda: self._in_flight is None, timeout=2.0)

    def _run(self) -> None:
        n = 0
        while True:
            with self._cond:
                while not self._closed:
                    wait = self._not_before - time.monotonic()
                    if self._wanted is not None and self._in_flight is None and wait <= 0:
                        break
                    self._idle = self._wanted is None
                    self._cond.wait(wait if wait > 0 and not self._idle and self._in_flight is None else None)
                    self._idle = False
                if self._closed:
                    return
                (key, marking), self._wanted = self._wanted, None
                self._in_flight, self._answered, self._ok = key, False, False
                self.stats.sent += 1
                self.stats.in_flight = True
            n += 1
            request = PredictRequest(system=self.system.name, digest=self.digest, seq=n,
                                     skillsets=statuses(self.system, marking), budget=self.budget,
                                     af=self.system.prediction.af_modes([p.name for p in self.system.properties]))
            handler = zenoh.handlers.Callback(_bind(self._on_reply, n, key), _bind(self._on_done, n, key))
            try:
                self.session.get(keys.predict(self.system.name), handler, payload=encode(request),
                                 timeout=self.timeout, express=True, cancellation_token=self._cancel,
                                 congestion_control=zenoh.CongestionControl.BLOCK)
            except Exception as exc:  # session closed under us
                log.warning("predict query failed: %s", exc)
                self._on_done(n, key)

    def _on_reply(self, n: int, key: Key, reply: zenoh.Reply) -> None:
        if reply.ok is None:
            with self._cond:
                self.stats.timed_out += 1
                self._answered = True
            log.warning("predict query #%d: error reply %s", n, _text(reply.err.payload) if reply.err else "")
            return
        try:
            msg = decode(reply.ok.payload.to_bytes(), PredictReply)
        except DecodeError as exc:
            msg, why = None, str(exc)
        else:
            why = "" if msg.ok and msg.seq == n and msg.digest == self.digest else (
                msg.error or f"reply seq {msg.seq}/digest {msg.digest[:8]} does not match query #{n}")
        with self._cond:
            self._answered = True
            if why:
                self.stats.failed += 1
            else:
                assert msg is not None
                self._ok = True
                self.stats.answered += 1
                self.stats.last_instance = msg.instance
                if msg.report is not None:
                    self.stats.last_time = msg.report.time
                    self.stats.last_markings = msg.report.markings
                    self.stats.last_complete = not msg.report.timeout_reached
        if why:
            log.warning("predict query #%d failed: %s", n, why)
        else:
            self.on_reply(key, msg)  # type: ignore[arg-type]

    def _on_done(self, n: int, key: Key) -> None:
        with self._cond:
            if not self._answered:
                self.stats.unanswered += 1
            if not self._ok:
                self._not_before = time.monotonic() + self.retry
            elif self._wanted is not None and self._wanted[0] == key:
                self._wanted = None  # wanted again while in flight, and now answered
            self._in_flight = None
            self.stats.in_flight = False
            self._cond.notify()


def _bind(fn: Callable, n: int, key: Key) -> Callable:
    return lambda *args: fn(n, key, *args)


def _text(payload: zenoh.ZBytes) -> str:
    try:
        return payload.to_string()
    except Exception:
        return repr(payload.to_bytes())
