"""The monitor service: the fast path of SPEC §1 as a Zenoh shell around :class:`Engine`.

Subscribes to ``keys.events(system, "*")``, recovering what an outage took from
the bridge's cache (:mod:`services.common.events`); per event it publishes
:class:`LiveState`, :class:`Verdicts` and :class:`UnsafeReport` (one step;
the three share the step's ``seq``).  It answers the model queryable, the command
check (``skinet/<system>/check/<client>``, :mod:`services.monitor.check`, with a request budget
per client: :class:`~services.common.ratelimit.RateLimiter`, issue 14) and ``get`` on its
four result keys (the last publication, for late joiners), holds a
liveliness token and asks the predictor for the live marking without ever
waiting for it (:mod:`services.monitor.prediction`); when a prediction for the
live marking arrives, the UnsafeReport of the same step is published again with
``prediction_stale=False`` together with the :class:`StateSpaceReport`.
Predictions are kept per marking (``prediction_cache``): a marking seen again is
fresh at once and not queried again.  A gap, a jump, a restarted bridge or events
that could not be recovered make it ask the bridge for the skillset's last status
(``keys.resync``) and apply it (see :meth:`Engine.check_seq`).  Bad payloads are counted and logged,
never raised (SPEC §7).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
import uuid
from dataclasses import dataclass

import zenoh

from services.common.events import event_subscriber
from services.common.ratelimit import CHECK_RATE_LIMIT, RateLimiter
from services.common.zenoh_config import undeclare
from services.monitor.check import Checker, Policy, request_from
from services.monitor.engine import Counters, Engine, MarkingKey, Step
from services.monitor.prediction import PredictionClient, PredictorStats
from skinet.system import System
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.convert import RiskTable, bundle
from skinet.wire.messages import (
    CanonicalEvent, CheckReply, CheckRequest, LiveState, PredictReply, StateSpaceReport, UnsafeReport, Verdicts,
)

log = logging.getLogger("skinet.monitor")
_LOG_FIRST = 10  # log the first occurrences of each problem, then every 1000th
MAX_EVENT = 64 << 10  # bytes; a canonical event is a few hundred
HISTORY_SLACK = 2.0  # seconds: events stamped this long before the monitor started are history


@dataclass(frozen=True)
class MonitorView:
    """A consistent copy of what the monitor last published, for operator views."""

    version: int  # grows with every publication
    state: LiveState
    verdicts: Verdicts
    unsafe: UnsafeReport
    state_space: StateSpaceReport | None
    counters: Counters
    predictor: PredictorStats


class Monitor:
    """A running monitor; build it with :func:`start_monitor`."""

    def __init__(self, session: zenoh.Session, system: System, *, instance_id: str | None = None,
                 budget: float = 1.0, query_timeout: float | None = None, retry: float = 0.5, stall: float = 0.5,
                 prediction_cache: int = 256, indirect: bool = True, express: bool = True,
                 check_policy: Policy | None = None, resync_timeout: float = 2.0, client: str = keys.LOCAL_CLIENT,
                 check_rate_limit: float = CHECK_RATE_LIMIT):
        self.session, self.system = session, system
        self.instance_id = keys.check_chunk(instance_id or uuid.uuid4().hex[:8], "instance id")
        name = keys.check_chunk(system.name, "system name")
        others = _tokens(session, keys.alive(name, "monitor", "*"))
        if others:
            raise SystemNameTaken(
                f"system '{name}' is already monitored by {others[0].rsplit('/', 1)[-1]} on this Zenoh network: "
                f"give each robot its own system name ([system] name in its .toml)")
        self.bundle = bundle(system)
        self.digest = self.bundle.digest
        self._model_payload = encode(self.bundle)
        self._engine = Engine(system, prediction_cache=prediction_cache)
        self.checker = Checker(system, check_policy)
        self.client = keys.check_chunk(client, "client name")
        self.check_limiter = RateLimiter(check_rate_limit)
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._version = 0
        self._closed = False
        self._last: dict[str, bytes] = {}
        self._waiters = 0  # threads in wait_change: notify only when someone listens
        self._resyncing: set[str] = set()  # skillsets with a resync query in flight
        self._started = time.time()
        self.resync_timeout = resync_timeout
        opts = dict(congestion_control=zenoh.CongestionControl.BLOCK, express=express)
        self._pub = {k: session.declare_publisher(key, **opts) for k, key in (
            ("state", keys.state(name)), ("verdicts", keys.verdicts(name)),
            ("unsafe", keys.unsafe(name)), ("state_space", keys.state_space(name)))}
        self._predict = PredictionClient(session, system, self.digest, self._on_prediction, client=self.client,
                                         budget=budget, timeout=query_timeout, retry=retry, stall=stall)
        with self._lock:
            self._publish(self._engine.initial())
        self._queryable = session.declare_queryable(keys.model(name, self.digest), self._on_model_query)
        self._check = session.declare_queryable(keys.check(name, "*"), self._on_check)
        # Late joiners (dashboards, watch) get the last publications with a get on their keys.
        self._latest = [session.declare_queryable(key, lambda q, n=name, k=key: self._on_latest(n, k, q))
                        for name, key in (("state", keys.state(system.name)), ("verdicts", keys.verdicts(system.name)),
                                          ("unsafe", keys.unsafe(system.name)),
                                          ("state_space", keys.state_space(system.name)))]
        self._predictors = session.liveliness().declare_subscriber(
            keys.alive("*", "predictor", "*"), self._on_predictor_token)
        for token in _tokens(session, keys.alive("*", "predictor", "*")):  # the pool before the first query
            self._predict.instance(token, True)
        self._sub, self._misses = event_subscriber(
            session, keys.events(name, "*"), zenoh.handlers.Callback(self._on_event, indirect=indirect), self._on_miss)
        # Declared last: whoever sees the token also sees the declarations above.
        self._token = session.liveliness().declare_token(keys.alive(name, "monitor", self.instance_id))
        self._twins = session.liveliness().declare_subscriber(keys.alive(name, "monitor", "*"), self._on_monitor_token)
        self._predict.want(self._engine.key, self._engine.marking())

    # -- public API -----------------------------------------------------------------

    @property
    def counters(self) -> Counters:
        with self._lock:
            return dataclasses.replace(self._engine.counters)

    @property
    def predictor_stats(self) -> PredictorStats:
        return self._predict.snapshot()

    def snapshot(self) -> MonitorView:
        """The latest published messages, counters and predictor statistics (thread-safe)."""
        with self._lock:
            last, version, counters = dict(self._last), self._version, dataclasses.replace(self._engine.counters)
        space = decode(last["state_space"], StateSpaceReport) if "state_space" in last else None
        return MonitorView(version, decode(last["state"], LiveState), decode(last["verdicts"], Verdicts),
                           decode(last["unsafe"], UnsafeReport), space, counters, self.predictor_stats)

    def wait_change(self, version: int, timeout: float | None = None) -> bool:
        """Block until something newer than ``version`` was published; False on timeout."""
        with self._changed:
            self._waiters += 1
            try:
                return self._changed.wait_for(lambda: self._version > version or self._closed, timeout)
            finally:
                self._waiters -= 1

    def close(self) -> None:
        """Undeclare everything (the session stays open: it may be shared)."""
        with self._changed:
            if self._closed:
                return
            self._closed = True  # callbacks still running return at once
            self._changed.notify_all()
        undeclare(self._misses, self._sub, self._predictors, self._twins, self._queryable, self._check, *self._latest,
                  self._token)
        self._predict.close()
        with self._lock:
            undeclare(*self._pub.values())

    # -- callbacks --------------------------------------------------------------------

    def _on_event(self, sample: zenoh.Sample) -> None:
        try:
            if len(sample.payload) > MAX_EVENT:
                raise DecodeError(f"event payload of {len(sample.payload)} bytes (limit {MAX_EVENT})")
            ev = decode(sample.payload.to_bytes(), CanonicalEvent)
            if ev.system != self.system.name:
                raise DecodeError(f"event of system '{ev.system}' on {sample.key_expr}")
        except DecodeError as exc:
            with self._lock:
                c = self._engine.counters
                c.received += 1
                c.malformed += 1
                self._warn(c.malformed, "malformed event payload: %s", exc)
            return
        if 0 < ev.stamp < self._started - HISTORY_SLACK:
            # The bridge's cache replayed to a monitor that starts late (zenoh.ext recovers
            # everything before a heartbeat's seq): history, not what happens now.
            with self._lock:
                self._engine.counters.received += 1
                self._engine.counters.history += 1
            return
        try:
            with self._lock:
                if self._closed:
                    return
                engine = self._engine
                engine.counters.received += 1
                fresh, problem, resync = engine.check_seq(ev)
                c = engine.counters
                if problem:
                    self._warn(c.duplicates + c.out_of_order + c.lost + c.jumps + c.restarts, "%s", problem)
                if fresh:
                    self._step(ev)
            if resync:
                self._ask_resync(ev.skillset)
        except Exception:  # a bug must not stop the monitor
            with self._lock:
                self._engine.counters.errors += 1
            log.exception("error while handling an event")

    def _on_miss(self, count: int) -> None:
        """Events an outage took that no cache could give back: counted, then every skillset resynced."""
        with self._lock:  # the next event shows the gap: check_seq counts it in lost and names it
            self._engine.counters.unrecovered += count
            self._warn(self._engine.counters.unrecovered, "%d events missed and not recoverable: resync", count)
        for c in self.system.components:
            self._ask_resync(c.name)

    def _ask_resync(self, skillset: str) -> None:
        """Ask the bridge for ``skillset``'s last status (one query in flight per skillset)."""
        with self._lock:
            if skillset in self._resyncing or self._closed:
                return
            self._resyncing.add(skillset)
        done = lambda: self._resync_done(skillset)  # noqa: E731
        try:
            self.session.get(keys.resync(self.system.name, skillset),
                             zenoh.handlers.Callback(self._on_resync, done), timeout=self.resync_timeout)
        except zenoh.ZError as exc:  # session closed under us
            log.warning("cannot ask for a resync of %s: %s", skillset, exc)
            done()

    def _resync_done(self, skillset: str) -> None:
        with self._lock:
            self._resyncing.discard(skillset)

    def _on_resync(self, reply: zenoh.Reply) -> None:
        try:
            if reply.ok is None:
                return
            ev = decode(reply.ok.payload.to_bytes(), CanonicalEvent)
            if ev.system != self.system.name:
                return
            with self._lock:
                if self._closed or not self._engine.resync(ev):
                    return
                self._engine.counters.resyncs += 1
                log.info("resync of %s from '%s' at #%d", ev.skillset, ev.source, ev.seq)
                self._step(ev)
        except DecodeError as exc:
            log.warning("bad resync reply: %s", exc)
        except Exception:
            log.exception("error while applying a resync")

    def _step(self, ev: CanonicalEvent) -> None:
        """Apply a checked event and publish its step (lock held)."""
        engine = self._engine
        step = engine.apply(ev)
        if step is None:  # a status confirming the live marking
            return
        self._publish(step)
        if step.divergence:
            self._warn(engine.counters.divergences, "divergence at %s#%d: %s", ev.skillset, ev.seq, step.divergence)
        if engine.prediction(step.key) is None:
            self._predict.want(step.key, engine.marking())

    def _on_prediction(self, key: MarkingKey, reply: PredictReply) -> None:
        try:
            table = RiskTable(self.system, reply.risks)
            with self._lock:
                if self._closed:
                    return
                if not self._engine.add_prediction(key, table):
                    self._predict.superseded()
                    return
                unsafe = self._engine.refresh()
                self._pub["unsafe"].put(unsafe)
                self._last["unsafe"] = unsafe
                if reply.report is not None:
                    space = encode(reply.report)
                    self._pub["state_space"].put(space)
                    self._last["state_space"] = space
                self._bump()
        except Exception:
            log.exception("error while applying a prediction")

    def _on_model_query(self, query: zenoh.Query) -> None:
        with query:
            query.reply(keys.model(self.system.name, self.digest), self._model_payload)

    def check(self, request: CheckRequest) -> CheckReply:
        """The command check at the live marking (SPEC §7; :mod:`services.monitor.check`)."""
        with self._lock:
            analysis, key, stale = self._engine.analysis()
            return self.checker.answer(request, analysis, key, seq=self._engine.seq, stale=stale)

    def _on_check(self, query: zenoh.Query) -> None:
        with query:
            try:
                client = keys.client_of(str(query.key_expr))
                if client is None:
                    query.reply_err(f"key '{query.key_expr}': the client chunk must be a name "
                                    "(skinet/<system>/check/<client>)")
                    return
                if not self.check_limiter.allow(client):  # before decoding: a refusal stays cheap
                    reply = CheckReply(system=self.system.name, skillset="", transition="", ok=False,
                                       error=self.check_limiter.refusal(client))
                else:
                    payload = query.payload.to_bytes() if query.payload is not None else None
                    request = request_from(self.system.name, payload, str(query.parameters))
                    reply = request if isinstance(request, CheckReply) else self.check(request)
                query.reply(keys.check(self.system.name, client), encode(reply))
            except Exception:  # a bug must not stop the monitor; the client gets an error reply
                log.exception("error while answering a check query")
                query.reply_err("internal error in the monitor's check (see its log)")

    def _on_latest(self, name: str, key: str, query: zenoh.Query) -> None:
        with query:
            with self._lock:
                payload = self._last.get(name)
            if payload is not None:
                query.reply(key, payload)

    def _on_predictor_token(self, sample: zenoh.Sample) -> None:
        alive = sample.kind == zenoh.SampleKind.PUT
        self._predict.instance(str(sample.key_expr), alive)
        if alive:
            with self._lock:
                stale = self._engine.prediction() is None
                key, marking = self._engine.key, self._engine.marking()
            if stale:
                self._predict.want(key, marking)

    def _on_monitor_token(self, sample: zenoh.Sample) -> None:
        """A monitor of the same system name appeared later (a link between robots came up)."""
        other = str(sample.key_expr).rsplit("/", 1)[-1]
        if sample.kind == zenoh.SampleKind.PUT and other != self.instance_id:
            log.error("another monitor (%s) of system '%s' is now reachable: two robots with the same system "
                      "name? give each its own ([system] name in its .toml)", other, self.system.name)

    # -- helpers (call with the lock held) --------------------------------------------

    def _publish(self, step: Step) -> None:
        for name, payload in (("state", step.live), ("verdicts", step.verdicts), ("unsafe", step.unsafe)):
            self._pub[name].put(payload)
            self._last[name] = payload
        self._bump()

    def _bump(self) -> None:
        self._version += 1
        if self._waiters:
            self._changed.notify_all()

    @staticmethod
    def _warn(count: int, fmt: str, *args: object) -> None:
        if count <= _LOG_FIRST or count % 1000 == 0:
            log.warning(fmt + " [#%d]", *args, count)


class SystemNameTaken(ValueError):
    """Another monitor of a system with the same name is reachable (two robots, one name)."""


def _tokens(session: zenoh.Session, key_expr: str, timeout: float = 2.0) -> list[str]:
    """The liveliness tokens alive under ``key_expr`` (returns as soon as the router answers)."""
    return sorted(str(r.ok.key_expr) for r in session.liveliness().get(key_expr, timeout=timeout) if r.ok is not None)


def start_monitor(session: zenoh.Session, system: System, **options: object) -> Monitor:
    """Start a monitor of ``system`` on ``session`` (which may be shared, SPEC §7).

    Options: ``instance_id``, ``budget`` (predictor exploration seconds, default 1),
    ``query_timeout`` (default 1.25 x budget + 3 s, see :func:`prediction.query_timeout`),
    ``retry`` (seconds between queries nobody answers, default 0.5), ``stall`` (seconds of silence after which a
    predictor instance counts as frozen and another one is asked, default 0.5), ``prediction_cache`` (markings whose prediction
    is kept, default 256), ``indirect`` (run the event callback in a Python thread
    of its own rather than on Zenoh's, default True), ``express`` (publish without
    batching, default True; False lets Zenoh batch the three messages of a step,
    which doubles burst throughput, see ``benchmarks/bench_latency.py``), ``check_policy``
    (a :class:`~services.monitor.check.Policy` for ``skinet/<system>/check``; default: warn,
    never deny), ``client`` (the client chunk of its predict queries: its router login,
    default ``local``), ``check_rate_limit`` (check requests per second per client, 0: no
    limit; default 20).
    """
    return Monitor(session, system, **options)  # type: ignore[arg-type]
