"""Model-level transitions from plain ROS 2 interfaces through a binding (docs/semantics.md §9).

The bridge plays the skillset manager of a bound skillset: :class:`BoundDeriver`
holds the skillset's net marking, as a manager holds its state, and turns each
observation into the canonical events a manager's statuses would have given:

- an action's ``GoalStatusArray`` (``<action>/_action/status``): a goal id first
  seen ACCEPTED (1), EXECUTING (2) or CANCELING (3) is ``k.start``; SUCCEEDED (4)
  ``k.success.m``, ABORTED (6) ``k.failure.m``, CANCELED (5) ``k.interrupt``; other
  changes nothing.  Goals of one array are taken in the order of their stamps.
  The mode ``m`` comes from the binding's conditions on the goal's result when it
  has some (the caller fetches the result with ``get_result``, :class:`ResultRequest`;
  later observations wait for it), else from its default;
- a lifecycle node's ``TransitionEvent`` (or the answer of ``get_state``): a goal
  state 1-4 sets the bound resource through the binding's table; transition states
  10-15 change nothing until they settle;
- a topic sample: a bound resource takes the first state whose condition holds; a
  bound event fires on the rising edge of its condition.

A resource change is named by the event of the model that explains it (enabled,
and leading to the observed state); a start by ``k.start`` when it is enabled.
*Drift* (:class:`Drift`: a goal accepted while the model says the skill cannot
start, a second concurrent goal, a resource state no event of the model reaches
from here, a topic value that matches no state, an event whose guard is false) is
reported with the message that showed it and what the model expected; the
observed marking is then adopted, as the monitor does (docs/semantics.md §7).  An event that
carries a drift says so (:attr:`~skinet.ros.derive.Derived.divergence`); a drift
that changes nothing in the marking (a second goal, a value matching no state, an
event whose guard is false) comes without an event (the bridge publishes it as a
status event carrying the drift, so that the monitor reports it too).

Start-up (live): until every bound interface has been read once (the last status
of each action, transient local, or the knowledge that its server has none; the
state of each lifecycle node; a first sample of each resource topic) the skillset
is *syncing* and nothing is published; the first event is then the initial
status built from those readings (``missing()`` says what is still awaited).
Replay starts from the model's initial marking (``synced=True``), and has no
results to fetch (``results=False``: modes from the defaults).

Pure: messages come in as plain values.  Cost per observation: one pass over the
enabled transitions of the net (and their invariant cascades).
"""

from __future__ import annotations

import uuid
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from skinet.lang.expr import holds, to_text
from skinet.lang.model import Skill
from skinet.net.build import idle_place, resource_place, running_place
from skinet.net.semantics import enabled, stabilize, stable_successors
from skinet.ros.binding import Binding, ResourceBinding, SkillBinding
from skinet.ros.derive import Derived
from skinet.system.model import Component
from skinet.wire.messages import SkillsetStatus

# action_msgs/msg/GoalStatus
STATUS_NAMES = {0: "UNKNOWN", 1: "ACCEPTED", 2: "EXECUTING", 3: "CANCELING", 4: "SUCCEEDED", 5: "CANCELED",
                6: "ABORTED"}
ACTIVE = frozenset({1, 2, 3})
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6
TERMINAL = frozenset({SUCCEEDED, CANCELED, ABORTED})
LIFECYCLE_NAMES = {0: "unknown", 1: "unconfigured", 2: "inactive", 3: "active", 4: "finalized", 10: "configuring",
                   11: "cleaningup", 12: "shuttingdown", 13: "activating", 14: "deactivating",
                   15: "errorprocessing"}
MAX_GOALS = 256  # goal ids remembered per action


@dataclass(frozen=True)
class Goal:
    """One entry of a ``GoalStatusArray``."""

    id: bytes  # the 16 bytes of its UUID
    stamp: float  # when the server accepted it (GoalInfo.stamp)
    status: int


def goal_text(goal_id: bytes) -> str:
    """The UUID as ROS 2 tools print it."""
    return str(uuid.UUID(bytes=bytes(goal_id))) if len(goal_id) == 16 else goal_id.hex()


def goals_from_plain(msg: Mapping[str, Any]) -> list[Goal]:
    """The goals of a decoded ``action_msgs/msg/GoalStatusArray`` (plain dicts); ``KeyError`` if malformed."""
    out = []
    for g in msg["status_list"]:
        info = g["goal_info"]
        stamp = info["stamp"]
        out.append(Goal(bytes(info["goal_id"]["uuid"]), stamp["sec"] + stamp["nanosec"] * 1e-9, int(g["status"])))
    return out


@dataclass(frozen=True)
class Drift:
    """A model divergence found by a binding (docs/semantics.md §9): what showed it, what was seen, what the model expected."""

    stamp: float
    skillset: str
    message: str
    observed: str
    expected: str

    def __str__(self) -> str:
        return f"{self.message}: {self.observed}, but {self.expected}"


@dataclass(frozen=True)
class ResultRequest:
    """The result of a terminal goal is needed to name its mode (``get_result``)."""

    skill: str
    action: str
    type: str
    goal: bytes


@dataclass
class BoundOutput:
    """What one observation gave: canonical events, drifts, results to fetch, notes and bad input."""

    events: list[Derived] = field(default_factory=list)
    drifts: list[Drift] = field(default_factory=list)
    results: list[ResultRequest] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    bad: list[tuple[str, str]] = field(default_factory=list)  # (kind, message): counted, logged once per kind

    def add(self, other: "BoundOutput") -> "BoundOutput":
        self.events += other.events
        self.drifts += other.drifts
        self.results += other.results
        self.notes += other.notes
        self.bad += other.bad
        return self


@dataclass
class _Action:
    binding: SkillBinding
    goals: OrderedDict[bytes, int] = field(default_factory=OrderedDict)  # goal id -> last status seen
    current: bytes | None = None  # the goal the model's skill runs
    others: list[bytes] = field(default_factory=list)  # concurrent goals (drift), in arrival order
    stopped: list[bytes] = field(default_factory=list)  # goals still active whose skill the model stopped
    read: bool = False


class BoundDeriver:
    """Derivation state of one bound skillset (not thread-safe: feed it in arrival order)."""

    def __init__(self, component: Component, binding: Binding, *, synced: bool = False, results: bool = True):
        self.component = component
        self.skillset = component.skillset
        self.net = component.net
        self.binding = binding
        self.results = results
        self.marking: int | None = component.net.initial if synced else None
        self.actions = {s.skill: _Action(s) for s in binding.skills}
        self.readings: dict[str, str] = {}  # resource -> state read during start-up
        self.topic_values: dict[str, bool | None] = {e.event: None for e in binding.events}  # last truth value
        self._waiting: ResultRequest | None = None
        self._held_status: tuple[int, str] = (0, "")  # the terminal status waiting for its result
        self._queued: list[Callable[[], BoundOutput]] = []
        self._skills = {k.name: k for k in self.skillset.skills}

    # -- start-up ---------------------------------------------------------------------------

    @property
    def synced(self) -> bool:
        return self.marking is not None

    @property
    def waiting(self) -> ResultRequest | None:
        """The result the derivation waits for before it goes on (later observations are queued)."""
        return self._waiting

    def missing(self) -> list[str]:
        """The readings start-up still waits for (empty once synced)."""
        if self.synced:
            return []
        out = [f"the status of {a.binding.action}" for a in self.actions.values() if not a.read]
        for r in self.binding.resources:
            if r.resource not in self.readings:
                out.append(f"the state of {r.lifecycle}" if r.lifecycle else f"a first {r.topic} message")
        return list(dict.fromkeys(out))  # two resources of one topic wait for one message

    def no_status(self, skill: str, stamp: float) -> BoundOutput:
        """The server of ``skill``'s action is up and has published no status: no goal yet."""
        action = self.actions[skill]
        if action.read:
            return BoundOutput()
        action.read = True
        return self._maybe_synced(stamp)

    def _maybe_synced(self, stamp: float) -> BoundOutput:
        if self.synced or self.missing():
            return BoundOutput()
        places = []
        for r in self.skillset.resources:
            places.append(resource_place(r.name, self.readings.get(r.name, r.initial)))
        for k in self.skillset.skills:
            action = self.actions.get(k.name)
            places.append(running_place(k.name) if action and action.current else idle_place(k.name))
        self.marking = self.net.marking_of(places)
        return BoundOutput([Derived(None, self.status(), stamp, "initial status")])

    # -- observations -----------------------------------------------------------------------

    def on_status(self, skill: str, goals: Sequence[Goal], stamp: float) -> BoundOutput:
        """A ``GoalStatusArray`` of ``skill``'s action."""
        return self._in_order(lambda: self._status(skill, goals, stamp))

    def on_result(self, skill: str, goal: bytes, result: Mapping[str, Any] | None, stamp: float) -> BoundOutput:
        """The result of a goal asked for by a :class:`ResultRequest` (``None``: it did not come in time)."""
        waiting = self._waiting
        if waiting is None or waiting.skill != skill or waiting.goal != goal:
            return BoundOutput(notes=[f"{self.skillset.name}: result of goal {goal_text(goal)} not waited for"])
        self._waiting = None
        out = self._outcome(skill, goal, self._held_status, stamp, result, result is None)
        while self._queued and self._waiting is None:
            out.add(self._queued.pop(0)())
        self._reconcile()
        return out

    def on_transition_event(self, resource: str, start: int, goal: int, stamp: float) -> BoundOutput:
        """A lifecycle ``TransitionEvent`` of ``resource``'s node (start and goal state ids)."""
        rb = self._resource(resource)
        what = f"{rb.transition_event}: {LIFECYCLE_NAMES.get(start, start)} -> {LIFECYCLE_NAMES.get(goal, goal)}"
        return self._in_order(lambda: self._lifecycle(rb, goal, stamp, what))

    def on_lifecycle_state(self, resource: str, state: int, stamp: float) -> BoundOutput:
        """The answer of ``get_state`` for ``resource``'s node."""
        rb = self._resource(resource)
        what = f"{rb.get_state}: {LIFECYCLE_NAMES.get(state, state)}"
        return self._in_order(lambda: self._lifecycle(rb, state, stamp, what))

    def on_topic(self, topic: str, msg: Mapping[str, Any], stamp: float) -> BoundOutput:
        """A sample of a bound topic (resources and events bound to it)."""
        return self._in_order(lambda: self._topic(topic, msg, stamp))

    def _in_order(self, step: Callable[[], BoundOutput]) -> BoundOutput:
        """Run ``step`` now, or after the result the deriver waits for (observations keep their order)."""
        if self._waiting is not None:
            self._queued.append(step)
            return BoundOutput()
        out = step()
        self._reconcile()
        return out

    def _reconcile(self) -> None:
        """A goal whose skill the model stopped (an invariant failed) no longer runs the skill."""
        if self.marking is None:
            return
        running = self.running()
        for skill, action in self.actions.items():
            if action.current is not None and skill not in running and self._waiting is None:
                action.stopped.append(action.current)
                del action.stopped[:-MAX_GOALS]
                action.current = action.others.pop(0) if action.others else None

    # -- actions ----------------------------------------------------------------------------

    def _status(self, skill: str, goals: Sequence[Goal], stamp: float,
                present: frozenset[bytes] | None = None) -> BoundOutput:
        """``present``: the ids of the whole array, when ``goals`` is what remains of it after a result."""
        action = self.actions[skill]
        where = action.binding.name("status")
        out = BoundOutput()
        if not self.synced:  # a reading: which goal runs now (every goal seen is known from here on)
            for g in sorted(goals, key=lambda g: (g.stamp, g.id)):
                action.goals[g.id] = g.status
                if g.status in ACTIVE and action.current is None:
                    action.current = g.id
                elif g.status in ACTIVE:
                    action.others.append(g.id)
            action.read = True
            _trim(action.goals)
            return self._maybe_synced(stamp)
        present = frozenset(g.id for g in goals) if present is None else present
        for g in sorted(goals, key=lambda g: (g.stamp, g.id)):
            before = action.goals.get(g.id)
            if before == g.status:
                continue
            if g.status not in STATUS_NAMES or g.status == 0:
                out.bad.append(("unknown goal status", f"{where}: goal {goal_text(g.id)} has status {g.status}, "
                                                       "not an action_msgs/msg/GoalStatus code"))
                continue
            action.goals[g.id] = g.status
            what = f"{where}: goal {goal_text(g.id)} {STATUS_NAMES[g.status]}"
            if before is None and g.status in ACTIVE:
                out.add(self._start(action, g.id, stamp, what))
            elif before is None:
                out.bad.append(("goal never accepted", f"{what} without having been seen accepted: no transition "
                                                       "derived (its start was not seen)"))
            elif before in TERMINAL:
                out.bad.append(("goal status after its end", f"{what} after {STATUS_NAMES[before]}: ignored"))
            elif g.status in TERMINAL:
                out.add(self._end(action, g.id, g.status, stamp, what))
                if self._waiting is not None:  # the rest of this array waits for the result
                    rest = [x for x in goals if action.goals.get(x.id) != x.status]
                    self._queued.insert(0, lambda: self._status(skill, rest, stamp, present))
                    break
        else:
            action.stopped = [g for g in action.stopped if g in present]
            for gone in [g for g in (action.current, *action.others) if g is not None and g not in present]:
                out.add(self._vanished(action, gone, stamp, where))
        _trim(action.goals)
        return out

    def _start(self, action: _Action, goal: bytes, stamp: float, what: str) -> BoundOutput:
        skill = action.binding.skill
        assert self.marking is not None
        if action.current is not None:
            action.others.append(goal)
            return BoundOutput(drifts=[Drift(stamp, self.skillset.name, what, f"a second goal of {skill}",
                                             f"{skill} already runs goal {goal_text(action.current)} (one goal at a "
                                             "time per skill)")])
        action.current = goal
        name = f"{skill}.start"
        after = self._fire(name)
        if after is not None:
            self.marking = after
            return BoundOutput([Derived(name, self.status(), stamp, what)])
        expected = self._why_not_start(self._skills[skill])
        self.marking = self._forced_start(self._skills[skill])
        drift = Drift(stamp, self.skillset.name, what, f"{skill} started", expected)
        return BoundOutput([Derived(name, self.status(), stamp, f"model divergence: {drift}", str(drift))], [drift])

    def _end(self, action: _Action, goal: bytes, status: int, stamp: float, what: str) -> BoundOutput:
        skill = action.binding
        if goal in action.others:
            action.others.remove(goal)
            return BoundOutput(notes=[f"{what}: a concurrent goal ended (the skill still runs "
                                      f"{goal_text(action.current or b'')})"])
        if goal in action.stopped:
            action.stopped.remove(goal)
            return BoundOutput(notes=[f"{what}: the model had already stopped {skill.skill} (an invariant failed)"])
        if goal != action.current:
            return BoundOutput(bad=[("goal never accepted", f"{what}: not a goal the skill runs")])
        outcome = skill.success if status == SUCCEEDED else skill.failure if status == ABORTED else None
        if outcome is not None and outcome.when and self.results:
            self._waiting = ResultRequest(skill.skill, skill.action, skill.type, goal)
            self._held_status = (status, what)
            return BoundOutput(results=[self._waiting])
        return self._outcome(skill.skill, goal, (status, what), stamp, None, False)

    def _outcome(self, skill: str, goal: bytes, held: tuple[int, str], stamp: float,
                 result: Mapping[str, Any] | None, timed_out: bool) -> BoundOutput:
        status, what = held
        action = self.actions[skill]
        binding = action.binding
        out = BoundOutput()
        if status == CANCELED:
            name = f"{skill}.interrupt"
        else:
            kind, outcome = ("success", binding.success) if status == SUCCEEDED else ("failure", binding.failure)
            try:
                mode = outcome.mode(result)
            except (KeyError, TypeError) as exc:
                out.bad.append(("result without a field", f"{what}: the result lacks {exc}: default mode"))
                mode = outcome.default
            if timed_out:
                out.notes.append(f"{what}: result not received in time: mode {mode!r} (the binding's default)")
            elif outcome.when and not self.results:
                out.bad.append(("result not recorded", f"{what}: the result is not in the recording: mode from the "
                                                       "binding's default"))
            if mode is None:
                name = f"{skill}.{kind}"
            else:
                name = f"{skill}.{kind}.{mode}" if mode else f"{skill}.{kind}"
            what += f" (mode {mode})" if mode else ""
        action.current = action.others.pop(0) if action.others else None
        assert self.marking is not None
        after = self._fire(name)
        if after is not None:
            self.marking = after
            out.events.append(Derived(name, self.status(), stamp, what))
        else:
            exists = any(t.name == name for t in self.net.transitions)
            expected = (f"{skill} is not running in the model" if exists else
                        f"the model has no transition {name}")
            self.marking = self._set_running(self.marking, skill, False)
            drift = Drift(stamp, self.skillset.name, what, f"{skill} ended", expected)
            out.drifts.append(drift)
            out.events.append(Derived(name, self.status(), stamp, f"model divergence: {drift}", str(drift)))
        if action.current is not None:  # a concurrent goal takes over: the skill starts again
            nxt, action.current = action.current, None
            out.add(self._start(action, nxt, stamp, f"{binding.name('status')}: goal {goal_text(nxt)} still active"))
        return out

    def _vanished(self, action: _Action, goal: bytes, stamp: float, where: str) -> BoundOutput:
        """An active goal missing from a status array: the server forgot it (it restarted)."""
        if goal in action.others:
            action.others.remove(goal)
            return BoundOutput()
        skill = action.binding.skill
        action.current = action.others.pop(0) if action.others else None
        assert self.marking is not None
        self.marking = self._set_running(self.marking, skill, action.current is not None)
        drift = Drift(stamp, self.skillset.name, f"{where}: goal {goal_text(goal)} absent",
                      f"{skill} no longer runs it", "no outcome of it was seen (did the action server restart?)")
        return BoundOutput([Derived(None, self.status(), stamp, f"model divergence: {drift}", str(drift))], [drift])

    def _why_not_start(self, skill: Skill) -> str:
        assert self.marking is not None
        states = self.resource_states()
        if skill.name in self.running():
            return f"{skill.name} already runs in the model"
        false = [f"'{p.name}' ({to_text(p.expr)})" for p in skill.preconditions if not holds(p.expr, states)]
        if false:
            shown = ", ".join(f"{r} is {s}" for r, s in states.items())
            return f"the model says {skill.name} cannot start: precondition {', '.join(false)} false ({shown})"
        return f"the model says {skill.name} cannot start here (its start effects are illegal moves)"

    # -- resources and events ---------------------------------------------------------------

    def _resource(self, name: str) -> ResourceBinding:
        return next(r for r in self.binding.resources if r.resource == name)

    def _lifecycle(self, rb: ResourceBinding, state_id: int, stamp: float, what: str) -> BoundOutput:
        if state_id >= 10 or state_id == 0:
            return BoundOutput()  # a transition state: wait until it settles
        state = rb.lifecycle_state(state_id)
        if state is None:
            label = LIFECYCLE_NAMES.get(state_id, str(state_id))
            if state_id not in (1, 2, 3, 4):
                return BoundOutput(bad=[("unknown lifecycle state", f"{what}: {state_id} is not a lifecycle state")])
            return self._unmatched(rb, stamp, what, f"lifecycle state '{label}' is bound to no state of "
                                                    f"{rb.resource}")
        return self._resource_state(rb, state, stamp, what)

    def _topic(self, topic: str, msg: Mapping[str, Any], stamp: float) -> BoundOutput:
        out = BoundOutput()
        for rb in self.binding.resources:
            if rb.topic != topic:
                continue
            shown = ", ".join(dict.fromkeys(c.shown(msg) for _, c in rb.states))
            try:
                state = next((s for s, c in rb.states if c.holds(msg)), None)
            except (KeyError, TypeError) as exc:
                out.bad.append(("message without a field", f"{topic}: a field is missing ({exc})"))
                continue
            what = f"{topic}: {shown}"
            if state is None:
                out.add(self._unmatched(rb, stamp, what, f"no state of {rb.resource} matches"))
            else:
                out.add(self._resource_state(rb, state, stamp, what))
        for eb in self.binding.events:
            if eb.topic != topic:
                continue
            try:
                now = eb.when.holds(msg)
            except (KeyError, TypeError) as exc:
                out.bad.append(("message without a field", f"{topic}: a field is missing ({exc})"))
                continue
            before, self.topic_values[eb.event] = self.topic_values[eb.event], now
            if self.synced and before is False and now:
                out.add(self._event(eb.event, stamp, f"{topic}: {eb.when.shown(msg)} ({eb.when.text})"))
        return out

    def _unmatched(self, rb: ResourceBinding, stamp: float, what: str, expected: str) -> BoundOutput:
        if not self.synced:
            return BoundOutput(bad=[("no state matches", f"{what}: {expected}")])
        return BoundOutput(drifts=[Drift(stamp, self.skillset.name, what, f"{rb.resource} observed", expected)])

    def _resource_state(self, rb: ResourceBinding, state: str, stamp: float, what: str) -> BoundOutput:
        if not self.synced:
            self.readings[rb.resource] = state
            return self._maybe_synced(stamp)
        assert self.marking is not None
        now = self.resource_states()[rb.resource]
        if now == state:
            return BoundOutput()
        place = self.net.place_index(resource_place(rb.resource, state))
        names = []
        for t in enabled(self.net, self.marking):
            if t.kind != "event" or t.name in names:
                continue
            if any(m >> place & 1 for m in stable_successors(self.net, self.marking, t)):
                names.append(t.name)
        what = f"{what} ({rb.resource} {now} -> {state})"
        if names:
            out = self._event(names[0], stamp, what, target=(rb.resource, state))
            if len(names) > 1:
                out.notes.append(f"{what}: explained by {', '.join(names)}; {names[0]} taken (first in the model)")
            return out
        self.marking = self._set_resource(self.marking, rb.resource, state)
        drift = Drift(stamp, self.skillset.name, what, f"{rb.resource} became {state}",
                      f"no event of the model takes {rb.resource} from {now} to {state} here")
        return BoundOutput([Derived(None, self.status(), stamp, f"model divergence: {drift}", str(drift))], [drift])

    def _event(self, name: str, stamp: float, what: str, target: tuple[str, str] | None = None) -> BoundOutput:
        assert self.marking is not None
        results = set()
        for t in enabled(self.net, self.marking):
            if t.name == name:
                results |= stable_successors(self.net, self.marking, t)
        if target is not None:
            place = self.net.place_index(resource_place(*target))
            results = {m for m in results if m >> place & 1}
        if not results:
            guard = self.skillset.event(name).guard
            expected = f"its guard {to_text(guard)} is false" if guard is not None else "its effects are illegal here"
            return BoundOutput(drifts=[Drift(stamp, self.skillset.name, what, f"event {name}",
                                             f"the model says {name} cannot happen now: {expected}")])
        self.marking = min(results)
        return BoundOutput([Derived(name, self.status(), stamp, what)])

    # -- markings ---------------------------------------------------------------------------

    def _fire(self, name: str) -> int | None:
        assert self.marking is not None
        results: set[int] = set()
        for t in enabled(self.net, self.marking):
            if t.name == name:
                results |= stable_successors(self.net, self.marking, t)
        return min(results) if results else None  # several only when invariants race: any is faithful

    def _forced_start(self, skill: Skill) -> int:
        """The marking after ``skill`` started against the model: running, its start effects applied,
        then its invariant cascade (what the model says a start does, preconditions aside)."""
        assert self.marking is not None
        m = self._set_running(self.marking, skill.name, True)
        for effect in skill.start:
            m = self._set_resource(m, effect.resource, effect.state)
        return min(stabilize(self.net, m))

    def _set_running(self, marking: int, skill: str, running: bool) -> int:
        i, e = self.net.place_index(running_place(skill)), self.net.place_index(idle_place(skill))
        marking &= ~((1 << i) | (1 << e))
        return marking | (1 << (i if running else e))

    def _set_resource(self, marking: int, resource: str, state: str) -> int:
        for s in self.skillset.resource(resource).states:
            marking &= ~(1 << self.net.place_index(resource_place(resource, s)))
        return marking | (1 << self.net.place_index(resource_place(resource, state)))

    def resource_states(self) -> dict[str, str]:
        assert self.marking is not None
        m, idx = self.marking, self.net.place_index
        return {r.name: next(s for s in r.states if m >> idx(resource_place(r.name, s)) & 1)
                for r in self.skillset.resources}

    def running(self) -> list[str]:
        assert self.marking is not None
        return [k.name for k in self.skillset.skills if self.marking >> self.net.place_index(running_place(k.name)) & 1]

    def status(self) -> SkillsetStatus | None:
        """The skillset's status as a manager would publish it (``None`` while syncing)."""
        if self.marking is None:
            return None
        return SkillsetStatus(resources=self.resource_states(), running=self.running())


def _trim(goals: OrderedDict[bytes, int]) -> None:
    while len(goals) > MAX_GOALS:
        goals.popitem(last=False)


__all__ = [
    "ACTIVE", "BoundDeriver", "BoundOutput", "Drift", "Goal", "LIFECYCLE_NAMES", "ResultRequest", "STATUS_NAMES",
    "TERMINAL", "goal_text", "goals_from_plain",
]
