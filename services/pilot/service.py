"""The pilot: goals in, safe skill requests out, on the live robot (docs/semantics.md §8, *The pilot*; issue 24).

Follows the monitor: its :class:`LiveState` on ``keys.state`` (asked with a ``get`` at
start and whenever a monitor appears; an answer that comes after the subscriber gave a
publication is dropped, since it may be older news of the same step), its :class:`UnsafeReport`
on ``keys.unsafe`` (``prediction_stale``) and its liveliness token.  Holds one goal (or mission, goal
after goal), set on the queryable ``keys.pilot_goal(system, <client>)``, and plans it
with :class:`skinet.plan.Planner` from the live marking, reusing the plan while
``plan.action(marking)`` answers and planning again when the marking leaves it (an
outcome, an event, the operator's own command: the operator keeps full control).

*guide* publishes the next command; *drive* also sends it through the
:class:`~services.pilot.act.Actuator`, only after the monitor's check
(``keys.check``, policy ``strict``) answered ``allow`` about the very step the command
was planned from (``CheckReply.seq`` = ``LiveState.seq``, neither state nor prediction
stale); a deny is a defect, logged with its reason and counted in ``denied``, never
sent.  After a command the pilot waits for its effect (an event of that skillset
after the step it was planned from); never two commands in flight; no reaction within
``response_timeout`` ends the goal ``failed: no response from <manager>``; a command the
robot refuses (:class:`~services.pilot.errors.Refused`) is asked again, and ends the goal after
``max_retries`` refusals.

Every skill seen running during a goal (and every start it sent) is followed to its end
(docs/pilot.md, *Missed outcomes*): one gone from a live step without its own outcome event
(a resync, a status the bridge derived, a new monitor, steps not received, the monitor's
``LiveState.missed``) goes on from the outcome the monitor or
:func:`~skinet.net.outcomes.infer_outcomes` makes unique, said in the status's ``notes``;
otherwise the goal holds with ``unknown`` until an operator's ``confirm`` (success, failure,
rerun): the pilot never starts such a skill again on its own.  A skill it started that runs
``outcome_timeout`` s makes it ask the manager for its status.  The operator's interrupt of
the pilot's skill counts against the retries and holds the goal until ``resume``; in guide
mode a command other than the one suggested is named; a ``run`` goal counts only a start
with its inputs (the actuator hears the requests).  A cancel sends nothing: the skills the pilot
started run on, unless it asks to interrupt them (``PilotGoalRequest.interrupt``); each is then
interrupted as a command is sent (the check, one in flight), never a run someone else started,
and given up (said so) when it cannot be sent within ``interrupt_wait`` s of the cancel
(docs/pilot.md, *Cancelling*).  New goals are counted before they are
parsed, and parsed and planned on a thread of their own, so cancels are answered meanwhile.

A skillset that is not ``live``, a model divergence seen while the goal runs (until ``resume``: later
steps do not clear it, the operator must accept the state the monitor adopted),
a prediction still pending ``PENDING_GRACE`` after its step (when a command is due) or an
operator's ``pause`` pause it.  A
skill that fails ``max_retries`` times in one goal ends it ``failed``.  The status
(:class:`PilotStatus`) is put on ``keys.pilot_status`` at every change and answered on
``get``.  Bad requests, an unknown system, a goal without a plan, no monitor, a manager
that is gone: a reason in the reply or the status, never a command, never a crash.
Cost per marking change: one ``plan.action`` (a few set lookups) while the plan covers
the marking, else one plan (:mod:`skinet.plan.planner`); one check query per command; a
pass over the skills followed (at most the system's skills), and per missed outcome one
:func:`~skinet.net.outcomes.infer_outcomes` of a single skill (``k`` firings).
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import zenoh

from services.common.zenoh_config import undeclare
from services.pilot.errors import ActError, Refused
from services.pilot.act import Actuator, default_actuator, inputs_problem, responder
from skinet.errors import SkinetError, SourceError
from skinet.net.outcomes import Inference, infer_outcomes, modes
from skinet.plan import Command, Goal, Plan, Planner, Reached, parse_goal, parse_goals
from skinet.plan.goalfile import count_goals
from skinet.ros.keys import KeyStyle
from skinet.system.model import System
from skinet.verify.explore import DEFAULT_MEMORY_LIMIT
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.limits import MAX_BUDGET
from skinet.wire.convert import marking_of, plan_steps
from skinet.wire.limits import PILOT_OUTCOME_TIMEOUT
from skinet.wire.messages import (
    OPEN_INTERRUPTS, CheckReply, CheckRequest, LiveState, MissedOutcome, PilotCommand, PilotGoalReply,
    PilotGoalRequest, PilotStatus, PlanStep, UnsafeReport,
)

log = logging.getLogger("skinet.pilot")
TICK = 0.1  # seconds between the worker's looks at timeouts
CHECK_WAIT = 1.0  # seconds the check may wait for a synced state and a fresh prediction
MAX_REQUEST = 256 << 10  # bytes of a goal request (a mission file's text)
MAX_GOALS = 32  # goals of one request
MAX_LOGGED = 300  # characters of a goal's text in the log
MAX_STATE = 1 << 20  # bytes of a LiveState or UnsafeReport read
PENDING_GRACE = 0.5  # seconds a step's prediction may take before the pilot says it is paused for it
RETRY_REFUSED = 1.0  # seconds before a check that gave no decision is asked again at the same step
OUTCOME_TIMEOUT = PILOT_OUTCOME_TIMEOUT  # seconds a skill it started may run before its manager is asked its status
INTERRUPT_WAIT = 30.0  # seconds after a cancel with interrupt within which an interrupt may still be sent
MAX_NOTES = 16  # notes a status lists (the goal's last ones)


@dataclass
class _Running:
    """A skill seen running (or started by the pilot) during a goal, whose end the pilot has not seen."""

    skillset: str
    skill: str
    ours: bool  # the pilot started it
    inputs: dict[str, Any] | None  # its start's inputs, when known
    marking: int | None = None  # its skillset's last live marking where it ran (None: not seen running yet)
    monitor: int = 0  # the monitor run (Pilot._runs) that showed it running last
    since: float = field(default_factory=time.monotonic)  # when it was started or first seen running
    asked: float = 0.0  # when its manager was last asked for its status (monotonic; 0: never)


@dataclass
class _Goal:
    """The goal (or mission) being followed."""

    id: int
    client: str
    mode: str
    goals: list[Goal]
    max_retries: int
    since: int  # the LiveState.seq when it was set: only later events count
    index: int = 0
    plan: Plan | None = None
    plans: list[Plan] = field(default_factory=list)  # the mission's, planned when it was set: reused while they cover
    retries: dict[str, int] = field(default_factory=dict)
    refused: dict[str, int] = field(default_factory=dict)  # 'skillset:transition' -> refusals by the robot
    commands: int = 0
    denied: int = 0
    paused_by: str = ""  # the client that paused it
    held: str = ""  # why it waits for `resume` (the operator interrupted the pilot's skill)
    running: dict[str, _Running] = field(default_factory=dict)  # 'skillset:skill' -> seen running, end not seen
    unknown: MissedOutcome | None = None  # an outcome that ended unseen and cannot be told: awaits `confirm`
    notes: list[str] = field(default_factory=list)  # what it assumed or was told (PilotStatus.notes)
    note: str = ""  # the last note while it matters: shown as the status's reason when there is no other
    recover: bool = False  # from outside Safe, send a recovery command first (PilotGoalRequest.recover)
    planned_at: dict[str, int] | None = None  # the marking g.plan was made at
    accepted_divergence: int = -1  # the step whose divergence `resume` accepted
    diverged_at: int = -1  # the last step with a divergence seen while following the goal
    diverged: str = ""  # its reason: the goal holds on it until `resume` accepts it
    end: str = ""  # reached, failed or cancelled
    reason: str = ""
    interrupts: dict[str, str] = field(default_factory=dict)  # after a cancel with interrupt: PilotStatus.interrupts
    interrupt_run: int = 0  # the monitor run (Pilot._runs) of that cancel: a restart loses track of the runs
    interrupt_due: float = 0.0  # when the interrupt sent must have shown its effect (monotonic)
    interrupt_by: float = 0.0  # after this (monotonic), an interrupt not sent yet is given up


def divergence_reason(st: LiveState) -> str:
    return (f"model divergence at step {st.seq} ({st.event}): {st.divergence}; resume to go on from the state the "
            "monitor adopted")


@dataclass
class _InFlight:
    command: PilotCommand
    seq: int  # the step it was planned from: its effect is an event of its skillset after it
    deadline: float  # monotonic
    manager: str


@dataclass
class _Due:
    command: PilotCommand
    seq: int
    goal: int
    unsafe: UnsafeReport  # the report that said the prediction of ``seq`` is fresh
    interrupt: bool = False  # the interrupt of a skill the pilot started, after a cancel that asked for it


class Pilot:
    """A running pilot; build it with :func:`start_pilot`."""

    def __init__(self, session: zenoh.Session, system: System, *, instance: str | None = None,
                 actuator: Actuator | None = None, response_timeout: float = 5.0, budget: float = 1.0,
                 client: str | None = None, typemap: Mapping[str, str] | None = None, style: KeyStyle = KeyStyle(),
                 outcome_timeout: float = OUTCOME_TIMEOUT, interrupt_wait: float = INTERRUPT_WAIT,
                 memory_limit: int | None = DEFAULT_MEMORY_LIMIT):
        self.session, self.system = session, system
        self.outcome_timeout, self.interrupt_wait = outcome_timeout, interrupt_wait
        self.name = keys.check_chunk(system.name, "system name")
        self.instance = keys.check_chunk(instance or uuid.uuid4().hex[:8], "instance id")
        self.client = keys.check_chunk(client or keys.LOCAL_CLIENT, "client name")
        if not 0 < budget <= MAX_BUDGET:  # a NaN fails too
            raise ValueError(f"planning budget {budget:g} s is not from 0 to {MAX_BUDGET:g} s (one day)")
        if memory_limit is not None and memory_limit <= 0:
            raise ValueError(f"memory limit {memory_limit} bytes is not positive")
        self.response_timeout, self.budget = response_timeout, budget
        self.typemap = dict(typemap or {})
        self.actuator: Actuator = actuator if actuator is not None else default_actuator(
            session, system, typemap, style, instance=f"pilot-{self.instance}")
        self.planner = Planner(system, memory_limit=memory_limit)
        self._names = {name: {t.name for t in net.transitions} for name, net in system.nets.items()}
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed = False
        self._state: LiveState | None = None
        self._unsafe: UnsafeReport | None = None
        self._heard = {"state": 0, "unsafe": 0}  # publications the subscribers gave (to date a get's answers)
        self._monitors: set[str] = set()
        self._runs = 0  # monitors that appeared: a skill last seen under an earlier one ended across a restart
        self._ask: list[str] = []  # skillsets whose manager is to be asked for its status (outcome timeout)
        self._goal: _Goal | None = None
        self._goals = 0
        self._inflight: _InFlight | None = None
        self._asked: tuple[int, int, UnsafeReport, float] | None = None  # goal, step, report, until: a refused check
        self._refusal = ""  # why that check did not allow
        self._seq = 0
        self._marked: tuple[LiveState | None, dict[str, int] | None] = (None, None)  # a LiveState's marking
        self._pending = (-1, 0.0)  # the step whose prediction is awaited, since when (monotonic)
        self._steps: tuple[Plan | None, list[PlanStep]] = (None, [])  # a plan's steps as messages, made once
        self._status = PilotStatus(system=self.name, pilot=self.instance, seq=0, stamp=time.time(),
                                   state="waiting for monitor", reason=self._no_monitor())
        self._payload = encode(self._status)
        self._parser = ThreadPoolExecutor(1, thread_name_prefix="skinet-pilot-goals")  # new goals, in order
        self._pub = session.declare_publisher(keys.pilot_status(self.name),
                                              congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        self._state_sub = session.declare_subscriber(keys.state(self.name), self._on_state)
        self._unsafe_sub = session.declare_subscriber(keys.unsafe(self.name), self._on_unsafe)
        self._monitor_sub = session.liveliness().declare_subscriber(keys.alive(self.name, "monitor", "*"),
                                                                     self._on_monitor, history=True)
        self._status_q = session.declare_queryable(keys.pilot_status(self.name), self._on_status_query)
        self._goal_q = session.declare_queryable(keys.pilot_goal(self.name, "*"), self._on_goal_query)
        self._pub.put(self._payload)
        self._token = session.liveliness().declare_token(keys.alive(self.name, "pilot", self.instance))
        self._worker = threading.Thread(target=self._run, name="skinet-pilot", daemon=True)
        self._worker.start()

    # -- public API ---------------------------------------------------------------------

    @property
    def status(self) -> PilotStatus:
        """The last published status."""
        with self._lock:
            return self._status

    def close(self) -> None:
        """Undeclare everything (the session stays open: it may be shared)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._wake.set()
        self._worker.join(CHECK_WAIT + 3.0)
        self._parser.shutdown(wait=False, cancel_futures=True)
        undeclare(self._token, self._goal_q, self._status_q, self._monitor_sub, self._unsafe_sub, self._state_sub)
        self.actuator.close()
        with self._lock:
            undeclare(self._pub)

    # -- what the monitor says -----------------------------------------------------------

    def _read(self, payload: zenoh.ZBytes, kind: type, what: str) -> Any:
        try:
            if len(payload) > MAX_STATE:
                raise DecodeError(f"{len(payload)} bytes")
            message = decode(payload.to_bytes(), kind)
            if message.system != self.name:
                raise DecodeError(f"system '{message.system}'")
            return message
        except DecodeError as exc:
            log.warning("%s not understood: %s", what, exc)
            return None

    def _on_state(self, sample: zenoh.Sample) -> None:
        state = self._read(sample.payload, LiveState, "live state")
        if state is not None:
            with self._lock:
                self._heard["state"] += 1
                self._take_state(state)
            self._wake.set()

    def _take_state(self, state: LiveState) -> None:
        """Follow one LiveState: effects of the command in flight, failures, run goals reached (lock held)."""
        last = self._state
        if last is not None and state.seq < last.seq:
            return  # an older publication
        self._state = state
        if last is not None and state.seq == last.seq:
            return  # the same step again (sync states changed)
        skillset, _, rest = state.event.partition(":")
        transition = rest.partition("#")[0]
        flight = self._inflight
        mine = None  # the pilot's command this event answers
        if flight is not None and skillset == flight.command.skillset and state.seq > flight.seq:
            self._inflight = None  # its effect (or an event that changed what it would do): plan again
            mine = flight.command
        g = self._goal
        gap = last is not None and state.seq > last.seq + 1  # publications the pilot did not get
        if g is not None and g.end and _open(g.interrupts):
            self._watch_interrupts(g, skillset, transition, gap)
        if g is None or g.end or state.seq <= g.since:
            return
        if state.divergence:
            g.diverged_at, g.diverged = state.seq, divergence_reason(state)
        self._follow(g, state, skillset, transition, mine, gap)

    def _follow(self, g: _Goal, state: LiveState, skillset: str, transition: str, mine: PilotCommand | None,
                gap: bool) -> None:
        """What one step means for the goal (lock held): outcomes, the operator's own commands, and the
        skills that ended unseen (docs/pilot.md, *Missed outcomes*)."""
        skill, _, rest = transition.partition(".")
        kind = rest.partition(".")[0]
        name = f"{skillset}:{skill}"
        if kind in ("start", "interrupt"):
            self._operator_command(g, skillset, skill, kind, mine)
        ended = g.running.pop(name, None) if kind in ("success", "failure", "interrupt") else None
        marking = self._marking()
        for key, r in list(g.running.items()):
            sync, status = state.sync.get(r.skillset), state.skillsets.get(r.skillset)
            if sync is None or sync.state != "live" or status is None or marking is None:
                continue  # the monitor cannot vouch for this skillset now
            if r.skill in status.running:
                r.marking, r.monitor = marking[r.skillset], self._runs
                continue
            listed = any((m.skillset, m.skill) == (r.skillset, r.skill) for m in state.missed)
            own = skillset == r.skillset
            modelled = own and transition in self._names[skillset]  # a step of the model, not a status adopted
            if listed or gap or r.monitor != self._runs or (own and not modelled) or \
                    (r.marking is not None and not modelled):
                del g.running[key]
                self._missed(g, r, state, marking[r.skillset], transition if own else "", gap)
            elif r.marking is not None:
                del g.running[key]  # ended by a step the monitor explained (an invariant, an event's cascade)
            if g.end:
                return
        for ss, status in state.skillsets.items():  # skills running now: their outcome is awaited
            sync = state.sync.get(ss)
            if sync is None or sync.state != "live" or marking is None:
                continue
            for k in status.running:
                r = g.running.setdefault(f"{ss}:{k}", _Running(ss, k, False, None))
                r.marking, r.monitor = marking[ss], self._runs
        if kind == "interrupt" and ended is not None and g.mode == "drive" and ended.ours and \
                (mine is None or mine.transition != f"{skill}.interrupt"):
            self._count_failure(g, name, f"{name} interrupted by the operator")
            if not g.end:
                g.held = (f"{name} interrupted by the operator ({g.retries[name]} of {g.max_retries} tries): resume "
                          "to go on")
                self._notes(g, f"{name} interrupted by the operator")
            return
        if kind in ("success", "failure"):
            self._outcome(g, skillset, transition, ended, "")

    def _operator_command(self, g: _Goal, skillset: str, skill: str, kind: str, mine: PilotCommand | None) -> None:
        """A start or interrupt seen: in guide mode, one other than the command suggested is named (lock held)."""
        if g.mode != "guide":
            return
        suggested = self._status.next if self._status.goal_id == g.id else None
        if suggested is None or (suggested.skillset, suggested.transition) == (skillset, f"{skill}.{kind}"):
            g.note = ""
            return
        did = "started" if kind == "start" else "interrupted"
        wanted = f"{suggested.skillset}:{suggested.transition.removesuffix('.start')}"
        self._notes(g, f"the operator {did} {skillset}:{skill}, not {wanted}: plan again")

    def _missed(self, g: _Goal, r: _Running, state: LiveState, after: int, step: str, gap: bool) -> None:
        """``r`` ended while the pilot did not see it: go on from the outcome the monitor or the model
        infers, else hold the goal until an operator says what it was (lock held)."""
        m = next((x for x in state.missed if (x.skillset, x.skill) == (r.skillset, r.skill)), None)
        if m is None:
            net = self.system.nets[r.skillset]
            how = ("while the monitor was restarted" if r.monitor != self._runs else
                   f"in steps of the monitor the pilot did not get (before step {state.seq})" if gap else
                   f"while the monitor resynced {r.skillset}" if step == "resync" else
                   f"without its response ({r.skillset}'s status at step {state.seq} shows it ended)")
            if r.marking is None:  # started, never seen running: it may have run, or not
                found = Inference(r.skill, None, modes(net, r.skill))
            else:
                found = infer_outcomes(net, r.marking, after, [r.skill])[0]
            m = MissedOutcome(skillset=r.skillset, skill=r.skill, gap=how, outcome=found.outcome,
                              candidates=list(found.candidates))
        name = f"{r.skillset}:{r.skill}"
        if m.outcome is None:
            if r.ours or g.mode == "guide" or self._concerns(g, r):
                g.unknown = m
                self._notes(g, f"{ended(m)}: outcome unknown")
                log.warning("goal %d: %s ended %s: outcome unknown (%s)", g.id, name, m.gap,
                            ", ".join(m.candidates) or "no mode explains the resources")
            return
        self._notes(g, f"{ended(m)}: {m.outcome.partition('.')[2]} inferred from the resources")
        log.warning("goal %d: %s", g.id, g.note)
        self._outcome(g, r.skillset, m.outcome, r, g.note)

    def _concerns(self, g: _Goal, r: _Running) -> bool:
        """Whether the goal being followed is a ``run`` of ``r``'s skill."""
        goal = g.goals[g.index]
        return goal.kind == "run" and (goal.skillset, goal.skill) == (r.skillset, r.skill)

    def _outcome(self, g: _Goal, skillset: str, transition: str, r: _Running | None, how: str) -> None:
        """An outcome of ``skillset``: a failure counts against the retries; a success may reach a ``run``
        goal, if its start had the goal's inputs; ``how``: the note of an outcome not seen (lock held)."""
        skill, _, outcome = transition.partition(".")
        name = f"{skillset}:{skill}"
        if outcome.startswith("failure"):
            self._count_failure(g, name, f"{name} failed", outcome.partition(".")[2] or "failure")
            if g.end:
                return
        goal = g.goals[g.index]
        if not goal.target(skillset, transition):
            return
        given = dict(goal.given(skillset, skill) or {})
        if r is not None and r.ours:
            other = None if r.inputs == given else r.inputs
        else:  # someone else's start: the inputs its request carried, when the actuator heard it
            check = getattr(self.actuator, "start_inputs", None)
            seen = check(skillset, skill, given) if check is not None else None
            other = None if seen is None or seen[0] else seen[1]
        if other is not None:
            self._notes(g, f"{name} ended in {outcome} after a start with inputs {other}, not the goal's {given}: it "
                           f"does not count for '{goal.text}'")
            return
        self._next_goal(g, how and f"{goal.text} reached by an outcome not seen: {how}")

    def _count_failure(self, g: _Goal, name: str, what: str, mode: str = "") -> None:
        g.retries[name] = g.retries.get(name, 0) + 1
        if g.retries[name] >= g.max_retries:
            last = f" (last: {mode})" if mode else ""
            self._end(g, "failed", f"{what} {g.retries[name]} times{last}")

    @staticmethod
    def _recovers(g: _Goal, marking: dict[str, int]) -> bool:
        """Whether ``g`` recovers first at ``marking``: asked to, and its plan from here is ``none`` with a way
        back into Safe (docs/semantics.md §8: from outside Safe no plan promises safety)."""
        return g.recover and g.plan is not None and g.plan.answer == "none" and bool(g.plan.recovery) and \
            g.planned_at == marking

    @staticmethod
    def _recovery(g: _Goal) -> Command:
        """The first recovery command, in the planner's fixed order (a start takes the goal's inputs)."""
        assert g.plan is not None
        skillset, transition = g.plan.recovery[0]
        skill, _, kind = transition.partition(".")
        inputs = g.goals[g.index].given(skillset, skill) if kind == "start" else None
        return Command(skillset, transition, dict(inputs or {}))

    def _notes(self, g: _Goal, note: str) -> None:
        g.note = note
        g.notes = (g.notes + [note])[-MAX_NOTES:]

    def _on_unsafe(self, sample: zenoh.Sample) -> None:
        report = self._read(sample.payload, UnsafeReport, "unsafe report")
        if report is not None:
            with self._lock:
                self._heard["unsafe"] += 1
                if self._unsafe is None or report.seq >= self._unsafe.seq or \
                        (self._state is not None and report.seq == self._state.seq):
                    self._unsafe = report
            self._wake.set()

    def _on_monitor(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._monitors.add(key)
                self._runs += 1
                self._state = self._unsafe = None  # a new monitor counts its steps from 0: ask it
                if self._inflight is not None:
                    self._inflight.seq = -1
                if self._goal is not None:
                    self._goal.since = -1
            else:
                self._monitors.discard(key)
                if not self._monitors:
                    self._state = self._unsafe = None
        self._wake.set()

    def _fetch(self) -> None:
        """Ask the monitor for its last state and unsafe report (a late joiner's ``get``).

        An answer that comes after the subscriber gave a publication is dropped: it may have left the
        monitor before that publication, with the same seq (a sync state's change publishes the step
        again), and the subscriber gives whatever changed since; the loop asks again if nothing is known."""
        for key, name, kind, take in ((keys.state(self.name), "state", LiveState, self._take_state),
                                      (keys.unsafe(self.name), "unsafe", UnsafeReport, None)):
            with self._lock:
                heard = self._heard[name]
            for reply in self.session.get(key, timeout=2.0):
                if reply.ok is None:
                    continue
                message = self._read(reply.ok.payload, kind, key)
                if message is None:
                    continue
                with self._lock:
                    if self._heard[name] != heard:
                        continue
                    if take is not None:
                        take(message)
                    elif self._unsafe is None or message.seq >= self._unsafe.seq:
                        self._unsafe = message

    # -- goal requests ------------------------------------------------------------------

    def _on_goal_query(self, query: zenoh.Query) -> None:
        """Answer a goal request: a new goal on the parser thread (parsing and planning take time, and a
        Zenoh callback that blocks holds up the session's later queries, cancels included), anything
        else at once."""
        try:
            answer = self._answer(query)
        except Exception:  # a bug must not stop the pilot; the client gets a reason
            log.exception("error while answering a goal request")
            answer = self._reject("internal error in the pilot (see its log)")
        if isinstance(answer, PilotGoalReply):
            self._reply(query, lambda: answer)
        else:
            request, client = answer
            try:
                self._parser.submit(self._reply, query, lambda: self._set_goal(request, client))
            except RuntimeError:  # closing
                self._reply(query, lambda: self._reject("the pilot is stopping"))

    def _reply(self, query: zenoh.Query, answer: Callable[[], PilotGoalReply]) -> None:
        with query:
            try:
                reply = answer()
            except Exception:  # a bug must not stop the pilot; the client gets a reason
                log.exception("error while answering a goal request")
                reply = self._reject("internal error in the pilot (see its log)")
            try:
                query.reply(str(query.key_expr), encode(reply))
            except zenoh.ZError:  # a key no reply can take (a wildcard): the reason as an error reply
                query.reply_err(reply.reason or "reply refused by Zenoh")
        self._wake.set()

    def _reject(self, reason: str) -> PilotGoalReply:
        return PilotGoalReply(system=self.name, accepted=False, reason=reason)

    def _answer(self, query: zenoh.Query) -> PilotGoalReply | tuple[PilotGoalRequest, str]:
        """The reply to ``query``, or a goal request and its client, to be set by :meth:`_set_goal`."""
        client = keys.client_of(str(query.key_expr))
        if client is None:
            return self._reject(f"key '{query.key_expr}': the client chunk must be a name "
                                f"({keys.pilot_goal(self.name, '<client>')})")
        size = 0 if query.payload is None else len(query.payload)
        if size > MAX_REQUEST:
            return self._reject(f"goal request of {size} bytes refused (limit {MAX_REQUEST} bytes)")
        if query.payload is None:
            return self._reject("empty goal request: send a PilotGoalRequest (msgpack)")
        try:
            request = decode(query.payload.to_bytes(), PilotGoalRequest)
        except DecodeError as exc:
            return self._reject(f"malformed goal request: {exc}")
        if request.system != self.name:
            return self._reject(f"unknown system '{request.system}': this pilot serves '{self.name}'")
        if request.op == "goal":
            return request, client
        with self._lock:
            g = self._goal
            if g is None or g.end:
                return self._reject(f"no goal is being followed: nothing to {request.op}")
            if request.op == "confirm":
                problem = self._confirm(g, request.answer, client)
                if problem:
                    return self._reject(problem)
            elif request.op == "mode":
                g.mode = request.mode
            elif request.op == "cancel":
                self._cancel(g, client, request.interrupt)
            elif request.op == "pause":
                g.paused_by = client
            else:  # resume: also accepts the divergence shown now
                g.paused_by = g.held = ""
                g.accepted_divergence = max(g.accepted_divergence, g.diverged_at)
                if self._state is not None and self._state.divergence:
                    g.accepted_divergence = max(g.accepted_divergence, self._state.seq)
            self._asked = None
            self._decide()
            return PilotGoalReply(system=self.name, accepted=True, goal_id=g.id)

    def _confirm(self, g: _Goal, answer: str | None, client: str) -> str:
        """The operator's answer about the outcome awaited; a reason when there is nothing to answer (lock held)."""
        m = g.unknown
        if m is None:
            return "no outcome is awaiting an answer: nothing to confirm"
        if answer is None:
            return "confirm needs an answer: success, failure or rerun"
        g.unknown = None
        self._notes(g, f"{ended(m)}: {answer} confirmed by {client}")
        log.info("goal %d: %s", g.id, g.note)
        if answer == "rerun":
            return ""
        net = self.system.nets[m.skillset]
        pool = [t for t in (m.candidates or modes(net, m.skill)) if t.startswith(f"{m.skill}.{answer}")] or \
            [t for t in modes(net, m.skill) if t.startswith(f"{m.skill}.{answer}")]
        goal = g.goals[g.index]
        wanted = f"{m.skill}.success.{goal.mode}" if goal.kind == "run" and goal.mode else ""
        transition = wanted if wanted in pool else pool[0] if pool else f"{m.skill}.{answer}"
        self._outcome(g, m.skillset, transition, None, g.note)
        return ""

    def _set_goal(self, request: PilotGoalRequest, client: str) -> PilotGoalReply:
        try:  # the goals counted before any is parsed: each is planned at once, within the budget
            count = len(request.goals) + (count_goals(request.mission, request.mission_name) if request.mission else 0)
            if count > MAX_GOALS:
                return self._reject(f"{count} goals: a mission has at most {MAX_GOALS}")
            several = len(request.goals) > 1
            goals = [parse_goal(self.system, text, request.inputs or None, f"<goal {n}>" if several else "<goal>",
                                types=self.typemap) for n, text in enumerate(request.goals, 1)]
            if request.mission:
                goals += parse_goals(request.mission, self.system, request.mission_name, self.typemap, MAX_GOALS)
        except SourceError as exc:
            return self._reject(str(exc))
        if not goals:
            return self._reject("no goals: give goals ('reach FORMULA', 'run SKILLSET:SKILL') or a mission")
        for goal in goals:  # a bound skill's goal message: refused now, not after the robot moved for it
            for (skillset, skill), values in goal.inputs.items():
                problem = inputs_problem(self.actuator, skillset, skill, values)
                if problem:
                    return self._reject(f"'{goal.text}': {problem}")
        with self._lock:
            g = self._goal
            if g is not None and not g.end and not request.replace:
                return self._reject(f"goal {g.id} of {g.client} is being followed ({self._status.state}): "
                                    "cancel it (--cancel), or send the new goal with --replace (the dashboard: "
                                    "'replace the goal that runs')")
            plans: list[Plan] = []
            if self._state is not None:
                try:
                    plans = self.planner.mission(goals, marking_of(self.system, self._state.skillsets), self.budget)
                except SkinetError as exc:
                    return self._reject(f"the live state cannot be planned from: {exc}")
                for n, p in enumerate(plans, 1):
                    if n == 1 and request.recover and p.answer == "none" and p.recovery:
                        continue  # it recovers first, then plans again
                    if p.answer not in ("strong", "cyclic"):
                        which = f"goal {n} ({p.goal.text})" if len(goals) > 1 else f"goal '{p.goal.text}'"
                        return self._reject(f"{which} has no plan from the live state: {p.answer}: {p.reason}")
            if g is not None and not g.end:
                self._end(g, "cancelled", f"replaced by goal {self._goals + 1} of {client}")
            self._goals += 1
            since = self._state.seq if self._state is not None else -1
            self._goal = _Goal(self._goals, client, request.mode, goals, request.max_retries, since,
                               plan=plans[0] if plans else None, plans=plans, recover=request.recover,
                               planned_at=marking_of(self.system, self._state.skillsets) if plans else None)
            self._asked = None
            log.info("goal %d of %s (%s): %s", self._goals, client, request.mode,
                     _cut("; ".join(x.text for x in goals), MAX_LOGGED))
            self._decide()
            first = plans[0] if plans else None
            return PilotGoalReply(system=self.name, accepted=True, goal_id=self._goals,
                                  answer=None if first is None else first.answer,
                                  moves=None if first is None else first.moves,
                                  steps=[] if first is None else plan_steps(first.steps))

    def _on_status_query(self, query: zenoh.Query) -> None:
        with query:
            with self._lock:
                payload = self._payload
            query.reply(keys.pilot_status(self.name), payload)

    # -- deciding and acting ------------------------------------------------------------

    def _run(self) -> None:
        fetched = False
        while not self._closed:
            try:
                if not fetched or (self._state is None and self._monitors):
                    self._fetch()
                    fetched = True
                with self._lock:
                    due = None if self._closed else self._decide()
                    ask, self._ask = self._ask, []
                for skillset in dict.fromkeys(ask):
                    self._ask_status(skillset)
                if due is not None:
                    self._act(due)
            except zenoh.ZError as exc:
                if self.session.is_closed():  # closed under a pilot not closed first: nothing left to do
                    log.warning("the pilot's session is closed (%s): it stops", exc)
                    return
                log.exception("error in the pilot")
            except Exception:  # a bug must not stop the pilot
                log.exception("error in the pilot")
            self._wake.wait(TICK)
            self._wake.clear()

    def _decide(self) -> _Due | None:
        """Publish what the pilot does now; the command to check and send, if one is due (lock held)."""
        g, st = self._goal, self._state
        if g is not None and g.end:
            f = self._inflight
            if f is not None and time.monotonic() >= f.deadline:  # a goal that ended: its command is forgotten
                log.warning("no effect of %s:%s seen from %s", f.command.skillset, f.command.transition, f.manager)
                self._inflight = None
            if _open(g.interrupts):
                return self._interrupting(g)
            return self._show(g.end, g.reason)
        waiting = self._no_monitor() if not self._monitors else \
            f"no live state from the monitor of {self.name} yet" if st is None else ""
        why = waiting or ("" if g is None or st is None else self._paused(g, st))
        flight = self._inflight
        if why and flight is not None:  # its effect cannot be seen now: the manager's time starts again after
            flight.deadline = time.monotonic() + self.response_timeout
        if waiting or st is None:
            return self._show("waiting for monitor", waiting)
        if g is None:
            return self._show("idle")
        if flight is not None and time.monotonic() >= flight.deadline:
            self._inflight = None
            self._end(g, "failed", f"no response from {flight.manager} within {self.response_timeout:g} s to "
                                   f"{flight.command.skillset}:{flight.command.transition}")
            return self._show(g.end, g.reason)
        if why:
            return self._show("paused", why)
        self._outcome_timeouts(g)
        if flight is not None:
            return self._show("waiting for outcome", f"the effect of {flight.command.skillset}:"
                                                     f"{flight.command.transition}", next_=flight.command)
        marking = self._marking()
        if marking is None:
            return self._show("paused", f"the live state of step {st.seq} names what {self.name} does not have")
        while True:
            if g.plan is None or (g.plan.action(marking) is None and not self._recovers(g, marking)):
                self._show("planning")
                try:
                    g.plan = self.planner.plan(g.goals[g.index], marking, self.budget)
                    g.planned_at = dict(marking)
                except SkinetError as exc:  # a marking the robot cannot be in (docs/semantics.md §3): nothing to plan from
                    g.plan = None
                    return self._show("paused", f"the live state of step {st.seq} cannot be planned from: {exc}")
            if self._recovers(g, marking):
                action = self._recovery(g)
                note = (f"recovering first with {action.skillset}:{action.transition} (back into Safe whatever its "
                        f"outcome), then planning again: {g.plan.reason.partition('; recover first')[0]}")
                if g.note != note:
                    self._notes(g, note)
                break
            if g.plan.answer not in ("strong", "cyclic"):
                self._end(g, "failed", f"no plan for '{g.goals[g.index].text}' from step {st.seq}: "
                                       f"{g.plan.answer}: {g.plan.reason}")
                return self._show(g.end, g.reason)
            action = g.plan.action(marking)
            if not isinstance(action, Reached):
                break
            self._next_goal(g)
            if g.end:
                return self._show(g.end, g.reason)
        if not isinstance(action, Command):
            running = ", ".join(f"{n}:{k}" for n, ss in st.skillsets.items() for k in ss.running)
            return self._show("waiting for outcome", f"the outcome of {running}{self._overdue(g)}")
        command = PilotCommand(skillset=action.skillset, transition=action.transition, inputs=dict(action.inputs))
        if g.mode == "guide":
            return self._show("guiding", next_=command)
        u = self._unsafe
        if u is None or u.seq != st.seq or u.prediction_stale:
            if self._pending[0] != st.seq:
                self._pending = (st.seq, time.monotonic())
            if time.monotonic() - self._pending[1] < PENDING_GRACE:  # the usual moment after every step
                return self._show("driving", f"waiting for the prediction of step {st.seq}", command)
            return self._show("paused", f"the prediction of step {st.seq} is pending", command)
        a = self._asked
        if a is not None and a[:3] == (g.id, st.seq, u) and time.monotonic() < a[3]:
            return self._show("paused", self._refusal, command)
        self._show("driving", next_=command)
        return _Due(command, st.seq, g.id, u)

    def _outcome_timeouts(self, g: _Goal) -> None:
        """Ask the manager of each skill the pilot started that has run ``outcome_timeout`` s without an
        outcome (or since it was last asked) for its status: a response lost while its link was down is
        then found (lock held; only while the goal is not paused, so its skillset is live)."""
        now = time.monotonic()
        for r in g.running.values():
            if r.ours and r.marking is not None and now - max(r.since, r.asked) >= self.outcome_timeout:
                r.asked = now
                self._ask.append(r.skillset)
                log.info("goal %d: no outcome of %s:%s within %g s: asking %s for its status", g.id, r.skillset,
                         r.skill, self.outcome_timeout, responder(self.system, r.skillset, r.skill))

    def _overdue(self, g: _Goal) -> str:
        asked = [f"{r.skillset}:{r.skill}" for r in g.running.values() if r.asked]
        return (f" (none seen within {self.outcome_timeout:g} s: status asked of its manager: "
                f"{', '.join(asked)})") if asked else ""

    def _ask_status(self, skillset: str) -> None:
        ask = getattr(self.actuator, "ask_status", None)
        if ask is None:
            log.warning("this pilot's actuator cannot ask %s for its status", skillset)
            return
        try:
            log.info("asked for its status: %s", ask(skillset))
        except ActError as exc:
            log.warning("cannot ask %s for its status: %s", skillset, exc.reason)

    def _paused(self, g: _Goal, st: LiveState) -> str:
        if g.unknown is not None:
            return unknown_reason(g.unknown)
        if g.held:
            return g.held
        if g.paused_by:
            return f"paused by {g.paused_by}"
        if not st.sync:
            return "the monitor does not say whether its state is synced: it cannot vouch for it"
        stale = [f"{name} is {s.state}" + (f": {s.reason}" if s.reason else "")
                 for name, s in st.sync.items() if s.state != "live"]
        if stale:
            return "; ".join(stale)
        if g.diverged_at > g.accepted_divergence:
            return g.diverged
        if st.divergence and st.seq > g.accepted_divergence:
            return divergence_reason(st)
        return ""

    def _act(self, due: _Due) -> None:
        """Ask the check about ``due``; send it only on ``allow`` about the step it was planned from."""
        c = due.command
        request = CheckRequest(skillset=c.skillset, transition=c.transition, wait=CHECK_WAIT,
                               policy="strict")
        reply: CheckReply | None = None
        problem = "the monitor's check did not answer"
        for r in self.session.get(keys.check(self.name, self.client), payload=encode(request),
                                  timeout=CHECK_WAIT + 2.0, express=True):
            if r.ok is not None:
                try:
                    reply = decode(r.ok.payload.to_bytes(), CheckReply)
                except DecodeError as exc:
                    problem = f"the check's answer is not understood: {exc}"
            else:
                problem = f"the check failed: {r.err.payload.to_string() if r.err is not None else '?'}"
        skill, _, kind = c.transition.partition(".")
        name = f"{c.skillset}:{skill}"
        with self._lock:
            g, st = self._goal, self._state
            if g is None or g.id != due.goal or st is None or st.seq != due.seq or self._inflight or \
                    not self._monitors or (g.interrupts.get(name) != "pending" if due.interrupt else
                                           g.end or self._paused(g, st)):
                return  # things moved on while the check was asked (a step, a sync state, a pause): decide again
            what = f"{c.skillset}:{c.transition}"
            if reply is None or not reply.ok:
                self._refuse(g, due, problem if reply is None else f"the check could not judge {what}: {reply.error}")
                return
            if reply.seq != due.seq:
                return  # the check judged another step: the state it planned from is gone
            if reply.state_stale or reply.prediction_stale:
                self._refuse(g, due, f"the check cannot vouch for step {due.seq}: "
                                     + (reply.state_reason or "its prediction is pending"))
                return
            if reply.decision != "allow":
                why = "; ".join(f"{r.property} ({r.constraint}): {r.reason}" for r in reply.reasons) or reply.decision
                if due.interrupt:  # asked for once, by the operator: the answer is theirs to act on
                    self._interrupt_ends(g, name, "not interrupted", f"not interrupted: the check answered "
                                         f"{reply.decision} for {what} at step {due.seq}: {why}", again=True)
                    return
                if reply.decision == "deny":
                    g.denied += 1
                    log.error("DEFECT: the check denied %s at step %d, which the plan gave: %s", what, due.seq, why)
                self._refuse(g, due, f"the check answered {reply.decision} for {what} at step {due.seq}: {why}",
                             again=False)
                return
            manager = responder(self.system, c.skillset, skill)
            self._inflight = _InFlight(c, due.seq, time.monotonic() + self.response_timeout, manager)
            g.commands += 1
            if due.interrupt:
                g.interrupts[name], g.interrupt_due = "sent", time.monotonic() + self.response_timeout
                self._notes(g, f"interrupt of {name} sent: the check allowed it at step {due.seq}")
                log.info("goal %d (cancelled): interrupting %s, which the pilot started", g.id, name)
                self._decide()
            else:
                g.note = ""
                if kind == "start":
                    g.running[name] = _Running(c.skillset, skill, True, dict(c.inputs), monitor=self._runs)
                self._show("waiting for outcome", f"the effect of {what}", c)
        try:
            sent = self.actuator.send(c)
            log.info("goal %d: sent %s:%s", due.goal, c.skillset, sent)
        except ActError as exc:
            if due.interrupt:
                with self._lock:
                    self._inflight = None
                    g = self._goal
                    if g is not None and g.id == due.goal and g.interrupts.get(name) == "sent":
                        refused = "the robot refused it" if isinstance(exc, Refused) else "it could not be sent"
                        self._interrupt_ends(g, name, "not interrupted", f"not interrupted: {refused}: {exc.reason}",
                                             again=True)
            elif isinstance(exc, Refused):
                self._refused(due, exc)
            else:
                self._failed(due, exc)

    def _refused(self, due: _Due, exc: Refused) -> None:
        """A command the robot refused: nothing changed on it, so it is asked again, up to max_retries times."""
        c = due.command
        log.warning("goal %d: %s", due.goal, exc.reason)
        with self._lock:
            self._inflight = None
            g = self._goal
            if g is not None and g.id == due.goal and not g.end:
                self._forget(g, c)
                name = f"{c.skillset}:{c.transition}"
                g.refused[name] = g.refused.get(name, 0) + 1
                if g.refused[name] >= g.max_retries:
                    self._end(g, "failed", f"{exc.reason} ({g.refused[name]} times)")
                else:
                    self._refuse(g, due, exc.reason)
                self._decide()

    def _failed(self, due: _Due, exc: ActError) -> None:
        """A command that could not be sent: the goal fails."""
        c = due.command
        with self._lock:
            self._inflight = None
            g = self._goal
            if g is not None and g.id == due.goal and not g.end:
                self._forget(g, c)
                self._end(g, "failed", f"cannot send {c.skillset}:{c.transition}: {exc.reason}")
                self._decide()

    # -- a cancel that interrupts (docs/pilot.md, *Cancelling*) -----------------------------

    def _cancel(self, g: _Goal, client: str, interrupt: bool) -> None:
        """End ``g`` cancelled; with ``interrupt``, each skill the pilot started for it whose end it has not
        seen is to be interrupted, through the check as any command it sends (lock held)."""
        reason = f"cancelled by {client}"
        if interrupt:
            g.interrupts = {name: "pending" for name, r in g.running.items() if r.ours}
            g.interrupt_run = self._runs
            g.interrupt_by = time.monotonic() + self.interrupt_wait
            if not g.interrupts:
                reason += "; no skill the pilot started runs: nothing to interrupt"
        self._end(g, "cancelled", reason, show=not g.interrupts)  # else the first status says what it interrupts

    def _interrupting(self, g: _Goal) -> _Due | None:
        """The interrupt of the first skill of ``g.interrupts`` still open, when it runs and the state and
        prediction of the step it is checked on are there; else the status says what it waits for, or what
        came of it (lock held)."""
        name, state = next((n, s) for n, s in g.interrupts.items() if s in OPEN_INTERRUPTS)
        skillset, _, skill = name.partition(":")
        command = PilotCommand(skillset=skillset, transition=f"{skill}.interrupt")

        def waiting(why: str = "") -> _Due | None:
            if state == "pending" and time.monotonic() >= g.interrupt_by:  # long after the ask: not the operator's
                return self._interrupt_ends(g, name, "not interrupted", f"not interrupted: not sent within "
                                            f"{self.interrupt_wait:g} s of the cancel" + (f" ({why})" if why else ""),
                                            again=True)
            return self._show("cancelled", f"{g.reason}; interrupting {name}, which the pilot started"
                                           + (f": {why}" if why else ""), next_=command)

        if self._runs != g.interrupt_run:
            return self._interrupt_ends(g, name, "not interrupted", f"not interrupted: {UNTOLD} (the monitor "
                                                                    "restarted)", again=True)
        if state == "sent":
            if time.monotonic() < g.interrupt_due:
                return waiting("sent, waiting for its effect")
            who = responder(self.system, skillset, skill)
            return self._interrupt_ends(g, name, "not interrupted", f"not interrupted: no response from {who} within "
                                                                    f"{self.response_timeout:g} s", again=True)
        st, u, flight = self._state, self._unsafe, self._inflight
        if flight is not None:  # its own start, say, whose effect comes first
            return waiting(f"waiting for the effect of {flight.command.skillset}:{flight.command.transition}")
        if st is None or not self._monitors:
            return waiting("waiting for the monitor's live state")
        sync = st.sync.get(skillset)
        if sync is None or sync.state != "live":
            return waiting(f"the monitor does not vouch for {skillset}" if sync is None else
                           f"{skillset} is {sync.state}" + (f": {sync.reason}" if sync.reason else ""))
        status = st.skillsets.get(skillset)
        if status is None or skill not in status.running:
            return self._interrupt_ends(g, name, "ended", "no longer runs: nothing to interrupt", again=True)
        if u is None or u.seq != st.seq or u.prediction_stale:
            return waiting(f"waiting for the prediction of step {st.seq}")
        a = self._asked
        if a is not None and a[:3] == (g.id, st.seq, u) and time.monotonic() < a[3]:
            return waiting(self._refusal)
        if time.monotonic() >= g.interrupt_by:
            return waiting()  # given up
        waiting()
        return _Due(command, st.seq, g.id, u, interrupt=True)

    def _watch_interrupts(self, g: _Goal, skillset: str, transition: str, gap: bool) -> None:
        """One step after a cancel with interrupt: the skills to interrupt that it ended, and those whose run
        the pilot can no longer tell is the one it started (lock held)."""
        skill, _, kind = transition.partition(".")
        for name, state in list(g.interrupts.items()):
            ss, _, k = name.partition(":")
            if state not in OPEN_INTERRUPTS or (ss != skillset and not gap):
                continue
            if gap:
                self._interrupt_ends(g, name, "not interrupted", f"not interrupted: {UNTOLD} (steps of the monitor "
                                                                 "were missed)")
            elif transition not in self._names[ss]:  # a resync, a status adopted
                self._interrupt_ends(g, name, "not interrupted", f"not interrupted: {UNTOLD} ({ss}'s state was taken "
                                                                 "from its manager anew)")
            elif k == skill and kind == "interrupt":
                self._interrupt_ends(g, name, "interrupted")
            elif k == skill and kind == "start":
                self._interrupt_ends(g, name, "not interrupted", "not interrupted: started again by someone else")
            elif k == skill:
                self._interrupt_ends(g, name, "ended", f"ended ({transition.partition('.')[2]}) before its interrupt")

    def _interrupt_ends(self, g: _Goal, name: str, state: str, what: str = "", again: bool = False) -> _Due | None:
        """What came of the interrupt of ``name`` (``state``, said as ``what``, by default the state): in the
        status's ``interrupts``, reason and notes (lock held); ``again``: decide at once what comes next (the
        next interrupt, or the end)."""
        g.interrupts[name] = state
        said = f"{name} {what or state}"
        g.reason = f"{g.reason}; {said}"
        self._notes(g, said)
        (log.info if state in ("interrupted", "ended") else log.warning)("goal %d (cancelled): %s", g.id, said)
        return self._decide() if again else None

    def _forget(self, g: _Goal, c: PilotCommand) -> None:
        """A start that was not sent, or that the robot refused: no outcome of it to await (lock held)."""
        skill = c.transition.partition(".")[0]
        r = g.running.get(f"{c.skillset}:{skill}")
        if c.transition.endswith(".start") and r is not None and r.ours and r.marking is None:
            del g.running[f"{c.skillset}:{skill}"]

    def _refuse(self, g: _Goal, due: _Due, reason: str, again: bool = True) -> None:
        """Hold ``due`` back: asked again at the next step or report, or (``again``) after RETRY_REFUSED s."""
        until = time.monotonic() + RETRY_REFUSED if again else float("inf")
        self._asked, self._refusal = (g.id, due.seq, due.unsafe, until), reason
        self._decide()

    def _next_goal(self, g: _Goal, reason: str = "") -> None:
        if g.index + 1 == len(g.goals):
            self._end(g, "reached", reason)
            return
        g.index += 1
        # The next goal's plan from when the mission was set: it serves wherever it covers the marking (a
        # plan's policy holds in its whole winning region, docs/semantics.md §8), so a goal change costs no planning.
        g.plan = g.plans[g.index] if g.index < len(g.plans) else None
        g.retries.clear()  # max_retries counts per goal of a mission

    def _end(self, g: _Goal, state: str, reason: str, show: bool = True) -> None:
        g.end, g.reason = state, reason
        (log.warning if state == "failed" else log.info)("goal %d %s%s", g.id, state, f": {reason}" if reason else "")
        if show:
            self._show(state, reason)

    def _no_monitor(self) -> str:
        return f"no monitor of {self.name} is running (no token on {keys.alive(self.name, 'monitor', '*')})"

    def _show(self, state: str, reason: str = "", next_: PilotCommand | None = None) -> None:
        """Publish the status if it changed (lock held); returns None for :meth:`_decide`."""
        g, st = self._goal, self._state
        fields: dict[str, Any] = dict(state=state, reason=reason, next=next_, state_seq=st.seq if st else 0)
        if g is not None:
            fields.update(goal_id=g.id, client=g.client, mode=g.mode, goals=[x.text for x in g.goals], index=g.index,
                          retries=dict(g.retries), commands=g.commands, denied=g.denied, unknown=g.unknown,
                          notes=list(g.notes), reason=reason or (g.note if not g.end else ""),
                          interrupts=dict(g.interrupts))
            plan = g.plan
            if plan is not None:
                if self._steps[0] is not plan:
                    self._steps = (plan, plan_steps(plan.steps))
                marking = self._marking()
                fields.update(answer=plan.answer, steps=self._steps[1],
                              moves_left=None if marking is None or g.end else plan.rank(marking))
        status = PilotStatus(system=self.name, pilot=self.instance, seq=self._status.seq, stamp=self._status.stamp,
                             **fields)
        if status == self._status:
            return None
        self._seq += 1
        self._status = status.model_copy(update={"seq": self._seq, "stamp": time.time()})
        self._payload = encode(self._status)
        if not self._closed:
            self._pub.put(self._payload)
        log.debug("status %s%s", state, f": {reason}" if reason else "")
        return None

    def _marking(self) -> dict[str, int] | None:
        """The live marking (None when unknown or not understood), computed once per LiveState."""
        st = self._state
        if st is None:
            return None
        if self._marked[0] is not st:
            try:
                self._marked = (st, marking_of(self.system, st.skillsets))
            except SkinetError:
                self._marked = (st, None)
        return self._marked[1]


UNTOLD = "the pilot cannot tell that the run is the one it started"  # why it no longer interrupts a skill


def _open(interrupts: Mapping[str, str]) -> bool:
    return any(state in OPEN_INTERRUPTS for state in interrupts.values())


def ended(m: MissedOutcome) -> str:
    """``SKILLSET:SKILL ended <the gap>``: the pilot's own gaps read as such ('while the monitor was
    restarted'); the monitor's, a phrase of their own, in parentheses."""
    how = m.gap if m.gap.startswith(("while ", "without ", "in ", "during ")) else f"unseen ({m.gap})"
    return f"{m.skillset}:{m.skill} ended {how}"


def unknown_reason(m: MissedOutcome) -> str:
    """The status's reason while the outcome of ``m`` awaits an operator's answer."""
    told = (f"{' or '.join(c.partition('.')[2] for c in m.candidates)} would explain the resources"
            if m.candidates else "no outcome of the model explains the resources")
    return (f"outcome unknown: {ended(m)}; {told}: confirm success, failure or rerun "
            "(the pilot does not start it again on its own)")


def _cut(text: str, limit: int) -> str:
    """``text`` on one line, cut to ``limit`` characters with the count of those left out."""
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else f"{flat[:limit]}… ({len(flat) - limit} more characters)"


def start_pilot(session: zenoh.Session, system: System, instance: str | None = None,
                actuator: Actuator | None = None, response_timeout: float = 5.0, budget: float = 1.0,
                client: str | None = None, typemap: Mapping[str, str] | None = None,
                style: KeyStyle = KeyStyle(), outcome_timeout: float = OUTCOME_TIMEOUT,
                interrupt_wait: float = INTERRUPT_WAIT, memory_limit: int | None = DEFAULT_MEMORY_LIMIT) -> Pilot:
    """Start a pilot of ``system`` on ``session`` (which may be shared, docs/semantics.md §7).

    ``instance``: its id in the liveliness token and the status (default: random);
    ``actuator``: how it acts (default: :func:`~services.pilot.act.default_actuator` on the keys of
    ``style``: the managers' request topics, which need the system's ``typemap``, and the bound skills'
    actions); ``response_timeout``: seconds a manager has to react to a command; ``budget``: planning
    seconds per goal; ``client``: its
    router login, the client chunk of its check queries (default ``local``); ``outcome_timeout``: seconds a
    skill it started may run without an outcome before its manager is asked for its status (and again
    after as many seconds); ``interrupt_wait``: seconds after a cancel with interrupt within which an interrupt
    may be sent (one that could not be, the monitor not vouching for its skillset say, is given up and said);
    ``memory_limit``: bytes of the whole process's resident memory past which a plan stops, ``unknown`` (None: no
    limit; a process that hosts other services counts their memory too: give it theirs, as ``skinet run`` does).
    """
    return Pilot(session, system, instance=instance, actuator=actuator, response_timeout=response_timeout,
                 budget=budget, client=client, typemap=typemap, style=style, outcome_timeout=outcome_timeout,
                 interrupt_wait=interrupt_wait, memory_limit=memory_limit)
