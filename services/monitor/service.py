"""The monitor service: the fast path of docs/semantics.md §1 as a Zenoh shell around :class:`Engine`.

Subscribes to ``keys.events(system, "*")``, recovering what an outage took from
the bridge's cache (:mod:`services.common.events`); per event it publishes
:class:`LiveState`, :class:`Verdicts` and :class:`UnsafeReport` (one step;
the three share the step's ``seq``).  It answers the model queryable, the command
check (``skinet/<system>/check/<client>``, :mod:`services.monitor.check`, with a request budget
per client, for new names and for all clients together: :class:`~services.common.ratelimit.RateLimiter`,
issues 14 and 31; its waiting requests shared fairly: :mod:`services.monitor.slots`) and ``get`` on its
five result keys (the last publication, for late joiners), holds a
liveliness token and asks the predictor for the live marking without ever
waiting for it (:mod:`services.monitor.prediction`); when a prediction for the
live marking arrives, the UnsafeReport of the same step is published again with
``prediction_stale=False`` together with the :class:`StateSpaceReport`.
Predictions are kept per marking (``prediction_cache``): a marking seen again is
fresh at once and not queried again.  An undecided one (the predictor's exploration was cut by its budget or
memory limit, ``StateSpaceReport.timeout_reached``) is asked again while its marking stays live, after 1, 2, 4,
8 and 16 s (:data:`REASK_FIRST`) and when a predictor appears: a loaded predictor may decide it later, and until
then the check says "could not decide", never allow.  A gap, a jump, a restarted bridge or events
that could not be recovered make it ask the bridge for the skillset's last status
(``keys.resync``) and apply it (see :meth:`Engine.check_seq`).  Bad payloads are counted and logged,
never raised (docs/semantics.md §7).

Honest live state (docs/semantics.md §7, :mod:`services.monitor.sync`): at start every
skillset is ``syncing`` and the monitor asks the bridge for its last status; its
events wait until the answer is applied.  The bridge's heartbeats
(``keys.heartbeat``), its liveliness token and its events keep a skillset
``live``; silence past ``lost_after`` seconds makes it ``lost``, and it resyncs
when its source is heard again.  Every change of these states publishes the
current step again (same ``seq``) with ``LiveState.sync`` and
``UnsafeReport.state_stale``.  A watchdog thread measures the silences and
answers the check requests that asked to ``wait`` (their queries are kept, never
a Zenoh callback thread blocked).

Model divergences and manager restarts are kept for the whole run
(:mod:`services.monitor.divergences`, the last 256): published on
``keys.divergences`` when the list changes (at most every ``DIVERGENCES_PERIOD``
seconds, the watchdog sending what a burst left) and answered on ``get``.

The five result keys are also published in rounds on ``keys.feed`` (:mod:`services.monitor.feed`), only while
someone subscribes to it: a view on the robot's own cores takes one Zenoh message per round instead of one per
result.

A ``tap`` (``--incidents``' ring, :mod:`services.monitor.incidents`) is handed the key, bytes and wall time of
each valid event received and of each message published, after the step's puts (an event after its step's
messages, with the time it came): no subscriber of the monitor's own keys and no thread of its own compete
with the event path.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import zenoh
from pydantic import BaseModel

from services.common.events import event_subscriber
from services.common.ratelimit import CHECK_RATE_LIMIT, CHECK_TOTAL_FACTOR, OK, RateLimiter
from services.common.zenoh_config import undeclare
from services.monitor.check import MAX_REQUEST, Checker, Policy, request_from
from services.monitor.slots import FREE, fair_slot
from services.monitor.divergences import DivergenceLog, event_name
from services.monitor.violations import ViolationOnsets, onset_reason
from services.monitor.engine import Counters, Engine, MarkingKey, Step
from services.monitor.feed import Feeder
from services.monitor.prediction import PredictionClient, PredictorStats
from services.monitor.sync import BOUND, SYNCING, SyncTracker
from skinet.errors import SourceError
from skinet.system.model import Marking, System
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.convert import RiskTable, bundle, missed_line
from skinet.wire.messages import (
    CanonicalEvent, CheckReply, CheckRequest, Divergences, Heartbeat, LiveState, PredictReply, SkillsetSync,
    StateSpaceReport, UnsafeReport, Verdicts,
)

Tap = Callable[[str, bytes, float], None]  # key, payload, wall time: Monitor(tap=...)
log = logging.getLogger("skinet.monitor")
_LOG_FIRST = 10  # log the first occurrences of each problem, then every 1000th
MAX_EVENT = 64 << 10  # bytes; a canonical event or a heartbeat is a few hundred
MAX_WAITING = 256  # check requests waiting at once, shared fairly between clients (services.monitor.slots)
MAX_REASON = 512  # bytes of a resync error reply kept as the skillset's reason
TICK = 0.1  # seconds between the watchdog's looks at silences and waiting checks
DIVERGENCES_PERIOD = 0.1  # seconds between publications of the divergence list (a burst is one message)
# An undecided prediction (exploration cut by the predictor's budget or memory limit) is asked again while its
# marking stays live: after 1, 2, 4, 8 then 16 s (a loaded predictor may decide it), then left undecided.
REASK_FIRST, REASK_TRIES = 1.0, 5
M = TypeVar("M", bound=BaseModel)


@dataclass
class CheckCounters:
    """What happened to the queries on the check key."""

    answered: int = 0  # replies with a decision
    errors: int = 0  # requests that could not be judged (bad payload, unknown name, bad policy)
    oversized: int = 0  # payloads or parameters over MAX_REQUEST bytes, refused before decoding
    rate_limited: int = 0  # refused by the per-client budget
    waited: int = 0  # answered after waiting for a synced state or a fresh prediction
    made_room: int = 0  # answered before their wait was over, for another client below its share of the slots


@dataclass
class _Waiting:
    deadline: float  # monotonic
    query: zenoh.Query
    request: CheckRequest
    client: str


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
    checks: CheckCounters


class Monitor:
    """A running monitor; build it with :func:`start_monitor`."""

    def __init__(self, session: zenoh.Session, system: System, *, instance_id: str | None = None,
                 budget: float = 1.0, query_timeout: float | None = None, retry: float = 0.5, stall: float = 0.5,
                 prediction_cache: int = 256, indirect: bool = True, express: bool = True,
                 check_policy: Policy | None = None, resync_timeout: float = 2.0, client: str = keys.LOCAL_CLIENT,
                 check_rate_limit: float = CHECK_RATE_LIMIT, lost_after: float = BOUND,
                 tap: Tap | None = None):
        self.session, self.system = session, system
        self._tap = tap
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
        self.check_limiter = RateLimiter(check_rate_limit, total=CHECK_TOTAL_FACTOR * check_rate_limit)
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._version = 0
        self._closed = False
        self._last: dict[str, bytes] = {}
        self._waiters = 0  # threads in wait_change: notify only when someone listens
        self._sync = SyncTracker((c.name for c in system.components), bound=lost_after, system=name)
        self._sync_seen = -1  # the tracker's version the engine's next messages carry
        self._sync_published = -1  # the version the last published step carries
        self._sync_shown: dict[str, SkillsetSync] = {}
        self.check_counters = CheckCounters()
        self._waiting: list[_Waiting] = []  # check requests waiting for a synced state or a fresh prediction
        self._wake = threading.Event()  # something changed that a waiting check may want
        self._behind: dict[str, tuple[float, CanonicalEvent]] = {}  # skillset -> (deadline, resync answer ahead)
        self._divergences = DivergenceLog(name, self.instance_id)
        self._onsets = ViolationOnsets()  # listed in the divergence list (kind violation)
        self._divergences_due = False  # the list changed since it was published
        self._divergences_sent = float("-inf")  # monotonic time of its last publication
        self._divergences_published = 0  # entries noted (listed or older) when it was last published
        self._undecided: dict[MarkingKey, tuple[float, int]] = {}  # key -> (monotonic time to ask again, tries)
        self.reasked = 0  # undecided predictions asked again
        self.resync_timeout, self.lost_after = resync_timeout, lost_after
        opts = dict(congestion_control=zenoh.CongestionControl.BLOCK, express=express)
        self._keys = {"state": keys.state(name), "verdicts": keys.verdicts(name), "unsafe": keys.unsafe(name),
                      "state_space": keys.state_space(name), "divergences": keys.divergences(name)}
        self._pub = {k: session.declare_publisher(key, **opts) for k, key in self._keys.items()}
        self._feed = Feeder(session, name, self.instance_id)  # the five, in rounds, for views on the robot
        self._predict = PredictionClient(session, system, self.digest, self._on_prediction, client=self.client,
                                         budget=budget, timeout=query_timeout, retry=retry, stall=stall)
        with self._lock:
            self._sync_fields()
            self._publish(self._engine.initial())
            self._last["divergences"] = self._divergences.payload(time.time())  # none yet, for late joiners
        self._queryable = session.declare_queryable(keys.model(name, self.digest), self._on_model_query)
        self._check = session.declare_queryable(keys.check(name, "*"), self._on_check)
        # Late joiners (dashboards, watch) get the last publications with a get on their keys.
        self._latest = [session.declare_queryable(key, lambda q, n=name, k=key: self._on_latest(n, k, q))
                        for name, key in (("state", keys.state(system.name)), ("verdicts", keys.verdicts(system.name)),
                                          ("unsafe", keys.unsafe(system.name)),
                                          ("state_space", keys.state_space(system.name)),
                                          ("divergences", keys.divergences(system.name)))]
        self._predictors = session.liveliness().declare_subscriber(
            keys.alive("*", "predictor", "*"), self._on_predictor_token)
        for token in _tokens(session, keys.alive("*", "predictor", "*")):  # the pool before the first query
            self._predict.instance(token, True)
        self._sub, self._misses = event_subscriber(
            session, keys.events(name, "*"), zenoh.handlers.Callback(self._on_event, indirect=indirect), self._on_miss)
        self._heartbeats = session.declare_subscriber(keys.heartbeat(name), self._on_heartbeat)
        self._sources = session.liveliness().declare_subscriber(keys.alive(name, "*", "*"), self._on_source_token,
                                                                history=True)
        # Declared last: whoever sees the token also sees the declarations above.
        self._token = session.liveliness().declare_token(keys.alive(name, "monitor", self.instance_id))
        self._twins = session.liveliness().declare_subscriber(keys.alive(name, "monitor", "*"), self._on_monitor_token)
        self._predict.want(self._engine.key, self._engine.marking())
        self._watchdog = threading.Thread(target=self._watch, name="skinet-monitor-watchdog", daemon=True)
        self._watchdog.start()
        for c in system.components:  # what happened before we started: the bridge's last statuses
            self._ask_resync(c.name)

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
            checks = dataclasses.replace(self.check_counters)
        space = decode(last["state_space"], StateSpaceReport) if "state_space" in last else None
        return MonitorView(version, decode(last["state"], LiveState), decode(last["verdicts"], Verdicts),
                           decode(last["unsafe"], UnsafeReport), space, counters, self.predictor_stats, checks)

    def divergences(self) -> Divergences:
        """The model divergences and manager restarts of this run as last published (thread-safe)."""
        with self._lock:
            payload = self._last["divergences"]
        return decode(payload, Divergences)

    @property
    def divergences_published(self) -> int:
        """How many divergences and restarts (listed or older) the last published list counts: cheap, to tell
        whether :meth:`divergences` changed."""
        with self._lock:
            return self._divergences_published

    def synced(self) -> bool:
        """Whether every skillset is ``live`` (docs/semantics.md §7)."""
        with self._lock:
            return self._sync.all_live()

    def last_seq(self, skillset: str, source: str) -> int | None:
        """The seq of the last event of ``skillset`` from ``source`` that was handled (applied, covered by a
        resync, or ignored as a duplicate); None before any."""
        with self._lock:
            last = self._engine.last_seq.get((skillset, source))
        return None if last is None else last[1]

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
        self._wake.set()
        self._watchdog.join(2.0)
        self._answer_waiting(everyone=True)
        undeclare(self._misses, self._sub, self._heartbeats, self._sources, self._predictors, self._twins,
                  self._queryable, self._check, *self._latest, self._token)
        self._predict.close()
        self._feed.close()
        with self._lock:
            undeclare(*self._pub.values())

    # -- callbacks --------------------------------------------------------------------

    def _read(self, sample: zenoh.Sample, kind: type[M], what: str) -> M | None:
        """``sample``'s payload as a ``kind`` of this system; None, counted in ``malformed`` and logged, else."""
        try:
            if len(sample.payload) > MAX_EVENT:
                raise DecodeError(f"{what} payload of {len(sample.payload)} bytes (limit {MAX_EVENT})")
            message = decode(sample.payload.to_bytes(), kind)
            if message.system != self.system.name:  # type: ignore[attr-defined]
                raise DecodeError(f"{what} of system '{message.system}' on {sample.key_expr}")  # type: ignore[attr-defined]
            return message
        except DecodeError as exc:
            with self._lock:
                c = self._engine.counters
                c.malformed += 1
                self._warn(c.malformed, "malformed %s payload: %s", what, exc)
            return None

    def _on_event(self, sample: zenoh.Sample) -> None:
        ev = self._read(sample, CanonicalEvent, "event")
        if ev is None:
            with self._lock:
                self._engine.counters.received += 1
            return
        received = time.time()
        try:
            with self._lock:
                if self._closed:
                    return
                self._engine.counters.received += 1
                # A skillset that is not live keeps its events until its resync answers (docs/semantics.md §7: what
                # its answer covers is history, whatever the events' stamps say).
                resync = self._sync.hold(ev) or self._handle(ev)
                self._note(ev, None, self._engine.seq)  # a restart is news even when its event is held or history
                self._settle()
            if self._tap is not None:  # after the step's puts, with the time it came
                self._tapped(str(sample.key_expr), sample.payload.to_bytes(), received)
            if resync:
                self._ask_resync(ev.skillset)
        except Exception:  # a bug must not stop the monitor
            with self._lock:
                self._engine.counters.errors += 1
            log.exception("error while handling an event")

    def _handle(self, ev: CanonicalEvent) -> bool:
        """Check ``ev``'s seq and apply it (lock held); whether to ask for a resync."""
        engine = self._engine
        fresh, problem, resync = engine.check_seq(ev)
        c = engine.counters
        if problem:
            self._warn(c.duplicates + c.out_of_order + c.lost + c.jumps + c.restarts, "%s", problem)
        if fresh:
            self._step(ev)
        last = engine.last_seq.get((ev.skillset, ev.source))
        if last is not None and last[0] == ev.epoch:
            self._sync.caught_up(ev.skillset, ev.source, ev.epoch, last[1])
        return resync

    def _on_miss(self, count: int) -> None:
        """Events an outage took that no cache could give back: counted, then every skillset resynced."""
        with self._lock:  # the next event shows the gap: check_seq counts it in lost and names it
            self._engine.counters.unrecovered += count
            self._warn(self._engine.counters.unrecovered, "%d events missed and not recoverable: resync", count)
        for c in self.system.components:
            self._ask_resync(c.name)

    def _on_heartbeat(self, sample: zenoh.Sample) -> None:
        hb = self._read(sample, Heartbeat, "heartbeat")
        if hb is None:
            return
        with self._lock:
            if self._closed:
                return
            self._sync.heartbeat(hb, [n for n in hb.pending if self._applied_after(n, hb)])
            self._settle()
            due = [n for n, b in hb.skillsets.items() if b.seq is not None and n in self._sync.skillsets
                   and self._sync.skillsets[n].state == SYNCING and not self._sync.outdated(n, hb.source)]
        for name in due:  # it has a status to give: ask at once rather than at the next retry
            self._ask_resync(name)

    def _applied_after(self, skillset: str, hb: Heartbeat) -> bool:
        """Whether an event of ``skillset`` newer than ``hb`` says was handled (lock held): a heartbeat
        sent before it may arrive after it."""
        last = self._engine.last_seq.get((skillset, hb.source))
        beat = hb.skillsets.get(skillset)
        return last is not None and last[0] == hb.epoch and beat is not None and \
            last[1] > (-1 if beat.seq is None else beat.seq)

    def _on_source_token(self, sample: zenoh.Sample) -> None:
        with self._lock:
            if self._closed:
                return
            self._sync.token(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            self._settle()
            due = [n for n, s in self._sync.skillsets.items() if s.state == SYNCING]
        for name in due:
            self._ask_resync(name)

    def _ask_resync(self, skillset: str) -> None:
        """Ask the bridge for ``skillset``'s last status (one query in flight per skillset)."""
        with self._lock:
            if self._closed or not self._sync.asking(skillset):
                return
        replied, refused, failed = [False], [""], [""]
        key = keys.resync(self.system.name, skillset)

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.err is not None:
                text = reply.err.payload.to_bytes()[:MAX_REASON].decode("utf-8", "replace")
                if reply.replier_id is None or text == "Timeout":  # Zenoh's own error: said with what was asked
                    failed[0] = text  # (a timed-out query's error has come with a replier id under load)
                else:  # the bridge knows its last status is outdated: still syncing
                    refused[0] = text
            replied[0] = self._on_resync(reply) or replied[0]

        def done() -> None:
            with self._lock:
                self._sync.answered(skillset, replied[0], refused[0], failed[0], key, self.resync_timeout)
                if not self._closed:
                    self._settle()

        try:
            self.session.get(key, zenoh.handlers.Callback(on_reply, done),
                             timeout=self.resync_timeout)
        except zenoh.ZError as exc:  # session closed under us
            log.warning("cannot ask for a resync of %s: %s", skillset, exc)
            done()

    def _on_resync(self, reply: zenoh.Reply) -> bool:
        """Apply a resync answer; whether one was (a live skillset's answer older than its events counts too)."""
        try:
            if reply.ok is None:
                return False
            ev = decode(reply.ok.payload.to_bytes(), CanonicalEvent)
            if ev.system != self.system.name or ev.status is None or ev.skillset not in self._sync.skillsets:
                return False
            resync = False
            with self._lock:
                if self._closed:
                    return False
                if self._sync.live(ev.skillset):  # a gap's or a new run's resync: the stream goes on
                    if self._engine.resync(ev):
                        log.info("resync of %s from '%s' at #%d", ev.skillset, ev.source, ev.seq)
                        self._take_status(ev)
                    return True
                resync = self._adopt(ev)
                self._settle()
            if resync:
                self._ask_resync(ev.skillset)
            return True
        except DecodeError as exc:
            log.warning("bad resync reply: %s", exc)
        except SourceError as exc:
            log.warning("resync reply with a status the model cannot read: %s", exc.diagnostics[0].message)
        except Exception:
            log.exception("error while applying a resync")
        return False

    def _adopt(self, ev: CanonicalEvent) -> bool:
        """A skillset that was not live is synced from ``ev`` (lock held; docs/semantics.md §7): its status becomes the
        marking, then its buffered events follow (those the answer covers are history); whether to resync."""
        engine = self._engine
        prev = engine.last_seq.get((ev.skillset, ev.source))
        continuing = prev is not None and prev[0] == ev.epoch  # the same run we followed before it went quiet
        engine.status_marking(ev)  # raises SourceError before anything changes
        upto = None
        if continuing:
            waited = [b.seq for b in self._sync.skillsets[ev.skillset].buffer if (b.source, b.epoch) == (ev.source,
                                                                                                        ev.epoch)]
            if max([prev[1], *waited]) < ev.seq:  # type: ignore[index]
                # Events up to the answer's are still on their way (the bridge's cache gives them back
                # after an outage), or lost: not live until they come, or the watchdog applies the
                # answer after the bound.
                upto = ev.seq
                self._behind[ev.skillset] = (time.monotonic() + self._sync.bound, ev)
        buffered = self._sync.synced(ev.skillset, ev.source, ev.epoch, upto)
        log.info("%s synced from '%s' at #%d (%d events waited)", ev.skillset, ev.source, ev.seq, len(buffered))
        resync = False
        if continuing:  # what it missed meanwhile is real: apply it (the cache gives it back, in order)
            for b in buffered:
                resync = self._handle(b) or resync
        else:
            self._take_status(ev)
            for b in buffered:
                resync = self._handle(b) or resync
        return resync

    def _catch_up(self) -> None:
        """Apply the resync answers whose events have not come within the bound (lock held)."""
        now = time.monotonic()
        for name, (deadline, ev) in list(self._behind.items()):
            last = self._engine.last_seq.get((ev.skillset, ev.source))
            if last is not None and last[0] == ev.epoch and last[1] >= ev.seq:
                del self._behind[name]
            elif now >= deadline:
                del self._behind[name]
                if self._engine.resync(ev):
                    log.warning("%s: events up to #%d from '%s' did not come: resynced", name, ev.seq, ev.source)
                    self._take_status(ev)
                self._sync.caught_up(name, ev.source, ev.epoch)

    def _take_status(self, ev: CanonicalEvent) -> None:
        """Adopt a resync answer's status (:meth:`Engine.adopt`) and publish the step it makes, if any."""
        self._sync_fields()  # before the step's messages are built
        step = self._engine.adopt(ev)
        if step is not None:
            if step.unchecked:
                log.warning("%s synced from '%s' at #%d: %s (what the robot did then is adopted, not judged)",
                            ev.skillset, ev.source, ev.seq, step.unchecked)
            self._publish(step)
            self._note_onsets(ev, step.seq)
            if self._engine.prediction(step.key) is None:
                self._predict.want(step.key, self._engine.marking())

    def _step(self, ev: CanonicalEvent) -> None:
        """Apply a checked event and publish its step (lock held)."""
        engine = self._engine
        self._sync_fields()  # before the step's messages are built
        step = engine.apply(ev)
        if step is None:  # a status confirming the live marking
            return
        self._publish(step)
        if step.divergence:
            self._warn(engine.counters.divergences, "divergence at %s#%d: %s", ev.skillset, ev.seq, step.divergence)
        for m in step.missed:
            log.warning("%s", missed_line(m))
        self._note(ev, step.reason, step.seq)  # the list shows the bridge's info beside it
        self._note_onsets(ev, step.seq)
        if engine.prediction(step.key) is None:
            self._predict.want(step.key, engine.marking())

    def _on_prediction(self, key: MarkingKey, reply: PredictReply) -> None:
        try:
            table = RiskTable(self.system, reply.risks)
            with self._lock:
                if self._closed:
                    return
                self._note_undecided(key, reply.report is not None and reply.report.timeout_reached)
                if not self._engine.add_prediction(key, table):
                    self._predict.superseded()
                    return
                unsafe = self._engine.refresh()
                self._pub["unsafe"].put(unsafe)
                self._last["unsafe"] = unsafe
                self._tapped(self._keys["unsafe"], unsafe)
                if reply.report is not None:
                    space = encode(reply.report)
                    self._pub["state_space"].put(space)
                    self._last["state_space"] = space
                    self._tapped(self._keys["state_space"], space)
                    self._feed.add(("unsafe", unsafe), ("state_space", space))
                else:
                    self._feed.add(("unsafe", unsafe))
                self._bump()
        except Exception:
            log.exception("error while applying a prediction")

    def _note_undecided(self, key: MarkingKey, undecided: bool) -> None:
        """Plan to ask again for an undecided prediction of ``key`` (lock held; :data:`REASK_FIRST`)."""
        if not undecided:
            self._undecided.pop(key, None)
            return
        tries = self._undecided.pop(key, (0.0, 0))[1]
        if tries >= REASK_TRIES:
            log.warning("the prediction of marking %s stays undecided after %d more tries: the predictor's budget "
                        "or memory limit is too small for it", key, tries)
            due = math.inf
        else:
            due = time.monotonic() + REASK_FIRST * 2 ** tries
        self._undecided[key] = (due, tries + 1)
        while len(self._undecided) > max(1, self._engine.prediction_cache):
            del self._undecided[next(iter(self._undecided))]

    def _reask(self) -> tuple[MarkingKey, Marking] | None:
        """The live marking, when its undecided prediction is due to be asked again (lock held)."""
        key = self._engine.key
        due, tries = self._undecided.get(key, (math.inf, 0))
        if time.monotonic() < due:
            return None
        self._undecided[key] = (math.inf, tries)  # until the answer
        self.reasked += 1
        return key, self._engine.marking()

    def _on_model_query(self, query: zenoh.Query) -> None:
        with query:
            query.reply(keys.model(self.system.name, self.digest), self._model_payload)

    def check(self, request: CheckRequest) -> CheckReply:
        """The command check at the live marking (docs/semantics.md §7; :mod:`services.monitor.check`).

        Names and the request's policy are checked before the lock is taken (suggestions cost
        difflib's time, never the events')."""
        bad = self.checker.unknown(request)
        if bad is not None:
            return bad
        policy = self.checker.policy_for(request)
        if isinstance(policy, CheckReply):
            return policy
        with self._lock:
            analysis, key, stale = self._engine.analysis()
            return self.checker.answer(request, analysis, key, seq=self._engine.seq, stale=stale,
                                       state=self._sync.stale(), policy=policy)

    def _on_check(self, query: zenoh.Query) -> None:
        kept = False
        try:
            client = keys.client_of(str(query.key_expr))
            if client is None:
                query.reply_err(f"key '{query.key_expr}': the client chunk must be a name "
                                "(skinet/<system>/check/<client>)")
                return
            reply, request = self._judge(query, client)
            if request is not None and request.wait > 0 and reply.ok and (reply.state_stale or reply.prediction_stale):
                kept = self._keep(query, request, client)
                if kept:
                    return
            query.reply(keys.check(self.system.name, client), encode(reply))
        except Exception:  # a bug must not stop the monitor; the client gets an error reply
            log.exception("error while answering a check query")
            query.reply_err("internal error in the monitor's check (see its log)")
        finally:
            if not kept:
                query.drop()

    def _judge(self, query: zenoh.Query, client: str) -> tuple[CheckReply, CheckRequest | None]:
        """The reply to a check query at once, and its request when it could be read (counted)."""
        c = self.check_counters
        size = 0 if query.payload is None else len(query.payload)
        parameters = str(query.parameters)
        if size > MAX_REQUEST or len(parameters) > MAX_REQUEST:  # before decoding: a refusal stays cheap
            with self._lock:
                c.oversized += 1
                self._warn(c.oversized, "check request of %d bytes from '%s' refused (limit %d)",
                           max(size, len(parameters)), client, MAX_REQUEST)
            return self._refusal(f"check request of {max(size, len(parameters))} bytes refused (limit "
                                 f"{MAX_REQUEST} bytes)"), None
        why = self.check_limiter.take(client)
        if why != OK:
            with self._lock:
                c.rate_limited += 1
                self._warn(c.rate_limited, "check requests of '%s' over the rate limit (%s) refused", client, why)
            return self._refusal(self.check_limiter.refusal(client, why)), None
        payload = query.payload.to_bytes() if query.payload is not None else None
        request = request_from(self.system.name, payload, parameters)
        reply = request if isinstance(request, CheckReply) else self.check(request)
        with self._lock:
            if reply.ok:
                c.answered += 1
            else:
                c.errors += 1
                self._warn(c.errors, "check request from '%s' not judged: %s", client, reply.error)
        return reply, None if isinstance(request, CheckReply) else request

    def _refusal(self, error: str) -> CheckReply:
        return CheckReply(system=self.system.name, skillset="", transition="", ok=False, error=error)

    def _keep(self, query: zenoh.Query, request: CheckRequest, client: str) -> bool:
        """Keep ``query`` until the state is synced and the prediction fresh, or ``request.wait`` s (the watchdog
        answers it); False when the client has its share of the slots already (answered at once).  A client
        below its share takes the oldest slot of the client holding the most when all are taken: that request
        is answered now, as it stands."""
        with self._lock:
            if self._closed:
                return False
            slot = fair_slot([w.client for w in self._waiting], client, MAX_WAITING)
            if slot is None:
                return False
            evicted = self._waiting.pop(slot) if slot != FREE else None
            if evicted is not None:
                self.check_counters.made_room += 1
            self._waiting.append(_Waiting(time.monotonic() + request.wait, query, request, client))
        if evicted is not None:
            self._answer(evicted)
        self._wake.set()
        return True

    def _answer_waiting(self, everyone: bool = False) -> None:
        """Answer the waiting checks whose state is synced and prediction fresh, or whose wait is over."""
        with self._lock:
            if not self._waiting:
                return
            ready = everyone or (self._sync.all_live() and self._engine.prediction() is not None)
            now = time.monotonic()
            due = [w for w in self._waiting if ready or now >= w.deadline]
            self._waiting = [w for w in self._waiting if w not in due]
        for w in due:
            self._answer(w)

    def _answer(self, w: _Waiting) -> None:
        """Answer a waiting check with the state as it is now."""
        try:
            reply = self.check(w.request)
            with self._lock:
                self.check_counters.waited += 1
            w.query.reply(keys.check(self.system.name, w.client), encode(reply))
        except Exception:
            log.exception("error while answering a check query")
        finally:
            w.query.drop()

    def _watch(self) -> None:
        """The watchdog: silences past the bound (lost skillsets), resyncs due again, waiting checks."""
        while not self._closed:
            self._wake.wait(TICK)
            self._wake.clear()
            if self.session.is_closed():  # closed under a monitor not closed first: nothing left to watch
                log.warning("the monitor's session is closed: its watchdog stops")
                return
            try:
                with self._lock:
                    if self._closed:
                        return
                    due = self._sync.tick()
                    self._catch_up()
                    self._settle()
                    self._publish_divergences()
                    again = self._reask()
                for name in due:
                    self._ask_resync(name)
                if again is not None:
                    self._predict.want(*again)
                self._answer_waiting()
            except zenoh.ZError as exc:
                if self.session.is_closed():  # closed under a monitor not closed first: nothing left to do
                    log.warning("the monitor's session is closed (%s): its watchdog stops", exc)
                    return
                log.exception("error in the monitor's watchdog")
            except Exception:  # a bug must not stop the watchdog
                log.exception("error in the monitor's watchdog")

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
            with self._lock:  # a new predictor may also decide what another one could not
                stale = self._engine.prediction() is None or self._engine.key in self._undecided
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
        """Publish a step built after :meth:`_sync_fields` (it carries the sync states of ``_sync_seen``)."""
        published = (("state", step.live), ("verdicts", step.verdicts), ("unsafe", step.unsafe))
        for name, payload in published:
            self._pub[name].put(payload)
            self._last[name] = payload
        self._sync_published = self._sync_seen
        self._bump()
        self._feed.add(*published)
        if self._tap is not None:  # after every put: the tap costs the step's warning nothing
            now = time.time()
            for name, payload in published:
                self._tapped(self._keys[name], payload, now)

    def _note(self, ev: CanonicalEvent, divergence: str | None, seq: int) -> None:
        """Keep ``ev`` in the divergence list if it diverged or follows a manager restart (lock held)."""
        if self._divergences.note(ev, divergence, seq, time.time()) is not None:
            self._divergences_due = True
            self._publish_divergences()

    def _note_onsets(self, ev: CanonicalEvent, seq: int) -> None:
        """List the properties this step made violated (lock held): views that join later see them."""
        onsets = self._onsets.step(self._engine.analysis()[0].violated)
        for prop in onsets:
            self._divergences.add("violation", seq, time.time(), ev.skillset, event_name(ev), onset_reason(prop))
        if onsets:
            self._divergences_due = True
            self._publish_divergences()

    def _publish_divergences(self) -> None:
        """Publish the divergence list if it changed, at most every DIVERGENCES_PERIOD seconds (lock held; the
        watchdog publishes what is left)."""
        now = time.monotonic()
        if not self._divergences_due or now - self._divergences_sent < DIVERGENCES_PERIOD:
            return
        payload = self._divergences.payload(time.time())
        self._pub["divergences"].put(payload)
        self._last["divergences"] = payload
        self._tapped(self._keys["divergences"], payload)
        self._feed.add(("divergences", payload))
        self._divergences_due, self._divergences_sent = False, now
        self._divergences_published = self._divergences.total
        self._bump()

    def _tapped(self, key: str, payload: bytes, t: float | None = None) -> None:
        """Hand a message received or published at wall time ``t`` (default: now) to the tap, if any; its failure is
        logged, never raised."""
        if self._tap is None:
            return
        try:
            self._tap(key, payload, time.time() if t is None else t)
        except Exception:  # a bug of the tap must not cost the monitor an event
            log.exception("error in the monitor's tap (--incidents, --foxglove)")

    def _sync_fields(self) -> None:
        """Give the engine the tracker's sync states for the next messages (and log what changed)."""
        if self._sync.version == self._sync_seen:
            return
        self._sync_seen = self._sync.version
        sync = self._sync.message()
        for name, s in sync.items():
            before = self._sync_shown.get(name)
            if before is None or (before.state, before.reason) != (s.state, s.reason):
                log.log(logging.WARNING if s.state == "lost" else logging.INFO, "%s %s%s", name, s.state,
                        f": {s.reason}" if s.reason else f" (from '{s.source}')")
        self._sync_shown = sync
        self._engine.set_sync(sync, self._sync.stale())

    def _settle(self) -> None:
        """Publish the current step again when the sync states changed since it was published."""
        self._sync_fields()
        if self._sync_published != self._sync_seen:
            self._publish(self._engine.republish())

    def _bump(self) -> None:
        self._version += 1
        if self._waiters:
            self._changed.notify_all()
        if self._waiting:
            self._wake.set()

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
    """Start a monitor of ``system`` on ``session`` (which may be shared, docs/semantics.md §7).

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
    default ``local``), ``check_rate_limit`` (check requests per second per client and new client names per
    second, five times as many from all clients together; 0: no limit; default 20), ``lost_after`` (seconds of silence from a skillset's source after
    which it is lost, default 2; docs/semantics.md §7).
    """
    return Monitor(session, system, **options)  # type: ignore[arg-type]
