"""Model-level transitions from what a skillset manager publishes (docs/semantics.md §1 bridge_ros2).

The manager (corpus README) publishes its ``SkillsetStatus`` after every change,
answers terminations, interrupts, invariant failures and rejected starts on
``skill/<k>/response`` and events on ``event_response``; a successful start gets
no response.  :class:`Deriver` diffs consecutive statuses and reads the responses
received since the previous status to name the transitions:

- skill READY -> RUNNING (or a new id): ``k.start``;
- RUNNING/INTERRUPTING -> READY with its response: ``k.success.m``,
  ``k.failure.m``, ``k.interrupt``; an ``INVARIANT_FAILURE`` response is the
  invariant cascade of another transition (the net fires it by priority, docs/semantics.md §3);
- a ``SUCCESS`` event response: the event named by the matching ``EventRequest``;
  internal events (response id equal to the status ``info``) and requests not seen
  are named from the model when exactly one event explains the change;
- rejected starts (``ALREADY_RUNNING``, ``PRECONDITION_FAILURE``,
  ``VALIDATE_FAILURE``, ``START_FAILURE``) and failed events change nothing in the
  model: they only give notes.

Several changes in one status become several transitions, in an order the net
accepts (checked by firing them with their invariant cascades from the previous
status); only the last carries the status.  When the changes cannot be named, one
event with ``transition=None`` and the status is produced and the monitor's
:class:`~skinet.system.live.LiveSystem` looks for a transition explaining it.

Pure: no I/O; messages come in as the plain dicts of
:func:`skinet.ros.typestore.to_plain`.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from itertools import permutations

from skinet.lang.model import Skillset
from skinet.net.build import idle_place, resource_place, running_place
from skinet.net.petrinet import PetriNet
from skinet.net.semantics import enabled, stable_successors
from skinet.ros.interfaces import EVENT_RESULTS, RESULTS, SKILL_STATES, status_field
from skinet.wire.messages import SkillsetStatus

READY = SKILL_STATES["READY"]
RESULT_NAMES = {v: k for k, v in RESULTS.items()}
EVENT_RESULT_NAMES = {v: k for k, v in EVENT_RESULTS.items()}
TERMINAL = frozenset(RESULTS[r] for r in ("SUCCESS", "INTERRUPT", "FAILURE", "INVARIANT_FAILURE"))
MAX_TRIGGERS = 6  # orders tried: at most 6! = 720 permutations
MAX_REMEMBERED = 256
MAX_PENDING = 64  # responses waiting for their status
MAX_SOLUTIONS = 64  # orders examined when an event name must be inferred


@dataclass(frozen=True)
class SkillView:
    state: int  # READY 0, RUNNING 1, INTERRUPTING 2
    id: str


@dataclass(frozen=True)
class Status:
    """A ``SkillsetStatus`` as the derivation needs it."""

    resources: Mapping[str, str]
    skills: Mapping[str, SkillView]  # model skill name -> view, in model order
    info: str = ""
    stamp: float = 0.0

    def running(self) -> list[str]:
        return [k for k, v in self.skills.items() if v.state != READY]

    def wire(self) -> SkillsetStatus:
        """The model-level view carried by canonical events (INTERRUPTING counts as running)."""
        return SkillsetStatus(resources=dict(self.resources), running=self.running())


@dataclass(frozen=True)
class SkillResponse:
    skill: str
    id: str
    result: int
    name: str = ""
    effect: bool = False
    postcondition: bool = True
    preconditions: Mapping[str, bool] = field(default_factory=dict)


@dataclass(frozen=True)
class EventResponse:
    id: str
    response: int


@dataclass(frozen=True)
class EventRequest:
    id: str
    name: str


@dataclass(frozen=True)
class Derived:
    """One canonical event to publish (the bridge adds system, skillset, seq, source)."""

    transition: str | None
    status: SkillsetStatus | None
    stamp: float
    info: str = ""
    divergence: str = ""  # a model divergence found while deriving it, with the message that showed it (docs/semantics.md §9)
    missed: tuple[str, ...] = ()  # skills this status shows ended without their response (missed outcomes)


@dataclass
class Output:
    """What one message gave: canonical events and log notes."""

    events: list[Derived] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


# -- plain dicts (rosbags messages through to_plain) -> views ----------------------------


def stamp_seconds(stamp: Mapping) -> float:
    """``builtin_interfaces/Time`` as seconds."""
    return float(stamp.get("sec", 0)) + float(stamp.get("nanosec", 0)) * 1e-9


def status_from_plain(skillset: Skillset, msg: Mapping) -> Status:
    """View of a decoded ``SkillsetStatus``; ``KeyError`` when a skill field is missing."""
    resources = {str(r["name"]): str(r["state"]) for r in msg.get("resources", [])}
    skills = {}
    for k in skillset.skills:
        s = msg[status_field(k)]
        skills[k.name] = SkillView(int(s["state"]), str(s["id"]))
    return Status(resources, skills, str(msg.get("info", "")), stamp_seconds(msg.get("stamp", {})))


def skill_response_from_plain(skillset: Skillset, skill: str, msg: Mapping) -> SkillResponse:
    from rosbags.typesys.base import normalize_fieldname

    pre = {p.name: bool(msg.get(normalize_fieldname(p.name), True)) for p in skillset.skill(skill).preconditions}
    return SkillResponse(skill, str(msg.get("id", "")), int(msg["result"]), str(msg.get("name", "")),
                         bool(msg.get("effect", False)), bool(msg.get("postcondition", True)), pre)


def event_response_from_plain(msg: Mapping) -> EventResponse:
    return EventResponse(str(msg.get("id", "")), int(msg["response"]))


def event_request_from_plain(msg: Mapping) -> EventRequest:
    return EventRequest(str(msg.get("id", "")), str(msg.get("name", "")))


def termination(r: SkillResponse) -> str:
    """Logical transition of a terminal response (``teleop.success.done``, ``k.inv.j``, ...)."""
    if r.result == RESULTS["INTERRUPT"]:
        return f"{r.skill}.interrupt"
    if r.result == RESULTS["INVARIANT_FAILURE"]:
        return f"{r.skill}.inv.{r.name}"
    kind = "success" if r.result == RESULTS["SUCCESS"] else "failure"
    return f"{r.skill}.{kind}.{r.name}" if r.name else f"{r.skill}.{kind}"


@dataclass
class _Trigger:
    names: tuple[str, ...]  # candidate logical names (several for an event whose name is unknown)
    known: bool  # False: the name is inferred from the model
    what: str  # for notes


class Deriver:
    """Derivation state of one skillset manager (not thread-safe: feed it in arrival order)."""

    def __init__(self, skillset: Skillset, net: PetriNet):
        self.skillset = skillset
        self.net = net
        self.last: Status | None = None
        self._responses: list[SkillResponse] = []  # terminal responses not yet used
        self._events: list[EventResponse] = []  # SUCCESS event responses not yet used
        self._requests: OrderedDict[str, str] = OrderedDict()  # event request id -> name
        self._handled: OrderedDict[tuple[str, str], None] = OrderedDict()  # (skill, id) stops already published
        self._handled_events: OrderedDict[str, None] = OrderedDict()  # event response ids seen
        self._rejected: OrderedDict[tuple[str, str], None] = OrderedDict()  # (skill, id) of rejected starts
        self._late_events = 0  # unexplained resource changes a late event response may still explain
        self._event_names = tuple(e.name for e in skillset.events)

    # -- inputs ---------------------------------------------------------------------

    def on_event_request(self, req: EventRequest) -> Output:
        self._requests[req.id] = req.name
        _trim(self._requests)
        return Output()

    def on_event_response(self, resp: EventResponse) -> Output:
        if resp.response != EVENT_RESULTS["SUCCESS"]:
            name = self._requests.pop(resp.id, "?")
            code = EVENT_RESULT_NAMES.get(resp.response, str(resp.response))
            return Output(notes=[f"{self.skillset.name}: event {name} (id '{resp.id}') refused: {code}"])
        if resp.id in self._handled_events:
            return Output(notes=[f"{self.skillset.name}: duplicate event response '{resp.id}' ignored"])
        if self.last is None or resp.id != self.last.info:  # internal events all share the info id
            self._handled_events[resp.id] = None
            _trim(self._handled_events)
        if self._late_events > 0:
            self._late_events -= 1
            self._requests.pop(resp.id, None)
            return Output(notes=[f"{self.skillset.name}: event response '{resp.id}' after its status (already published)"])
        self._events.append(resp)
        del self._events[:-MAX_PENDING]
        return Output()

    def on_skill_response(self, r: SkillResponse) -> Output:
        code = RESULT_NAMES.get(r.result, str(r.result))
        where = f"{self.skillset.name}: {r.skill}"
        if r.result not in TERMINAL:
            self._rejected[(r.skill, r.id)] = None
            _trim(self._rejected)
        if r.result == RESULTS["ALREADY_RUNNING"]:
            return Output(notes=[f"{where}: start rejected, ALREADY_RUNNING (running id '{r.id}')"])
        if r.result == RESULTS["PRECONDITION_FAILURE"]:
            failed = ", ".join(p for p, ok in r.preconditions.items() if not ok) or "?"
            return Output(notes=[f"{where}: start '{r.id}' rejected, PRECONDITION_FAILURE ({failed})"])
        if r.result not in TERMINAL:
            return Output(notes=[f"{where}: start '{r.id}' rejected, {code}"])
        if (r.skill, r.id) in self._handled:
            return Output(notes=[f"{where}: {code} response '{r.id}' after its status (already published)"])
        self._responses.append(r)
        del self._responses[:-MAX_PENDING]
        return Output()

    def awaits(self, st: Status) -> str | None:
        """The response that ``st`` needs and that has not come yet (``None``: ``st`` can be named now).

        A manager publishes its responses before its status, but each topic crosses a
        gateway on its own route, so the status may overtake them; the bridge holds
        such a status until they come (or for a bounded time).  Cost: one pass over
        the skills.
        """
        prev = self.last
        if prev is None:
            return None
        responses = {(r.skill, r.id): r for r in self._responses}
        pending = responses.keys() | self._rejected.keys()
        triggered = cascade = False  # a change of its own; an invariant failure (needs a trigger)
        for k, now in st.skills.items():
            before = prev.skills.get(k, SkillView(READY, ""))
            was, running = before.state != READY, now.state != READY
            if was and (not running or now.id != before.id):
                if (k, before.id) not in responses:
                    return f"the response of {k} '{before.id}'"
                failed = responses[(k, before.id)].result == RESULTS["INVARIANT_FAILURE"]
                triggered, cascade = triggered or not failed, cascade or failed
            if not running and not was and now.id != before.id and (k, now.id) not in pending:
                return f"the response of {k} '{now.id}'"
            triggered = triggered or (running and (not was or now.id != before.id)) or \
                (not running and not was and now.id != before.id)
        if not triggered and (cascade or prev.resources != st.resources) and not self._events:
            return "an event response"
        return None

    def on_status(self, st: Status) -> Output:
        prev, self.last = self.last, st
        if prev is None:
            self._responses.clear()
            self._events.clear()
            return Output([Derived(None, st.wire(), st.stamp, "initial status")])
        stops, starts, cascade, unexplained = self._skill_changes(prev, st)
        triggers = stops + self._event_triggers(prev, st) + starts
        out = Output()
        if not triggers and not unexplained:
            if prev.wire() != st.wire():
                # An event response may still come after its status (topics are not ordered
                # with one another on every path); remember that one is expected.
                self._late_events += self._event_explains(prev, st)
                out.events.append(Derived(None, st.wire(), st.stamp, "unexplained change"))
                out.notes.append(f"{self.skillset.name}: status changed without a response or request naming it")
            return out
        info = "; ".join(
            ([f"invariant failures: {', '.join(cascade)}"] if cascade else [])
            + ([f"unexplained: {', '.join(unexplained)}"] if unexplained else [])
        )
        order = None if unexplained else self._order(prev, st, triggers)
        if order is not None:
            for i, name in enumerate(order):
                last = i == len(order) - 1
                out.events.append(Derived(name, st.wire() if last else None, st.stamp, info if last else ""))
            return out
        # The model cannot explain the change: one event with the status; a single named
        # trigger keeps its name so that the monitor's divergence report says what happened.
        single = triggers[0].names[0] if len(triggers) == 1 and triggers[0].known and not unexplained else None
        seen = ", ".join(t.what for t in triggers)
        info = "; ".join(x for x in (info, f"model cannot order: {seen}" if seen else "") if x)
        missed = tuple(k for k, before in prev.skills.items() if before.state != READY and
                       f"{k} stopped without a response" in unexplained)
        out.events.append(Derived(single, st.wire(), st.stamp, info, missed=missed))
        out.notes.append(f"{self.skillset.name}: status not explained by the model ({info})")
        return out

    def _skill_changes(self, prev: Status, st: Status) -> tuple[list[_Trigger], list[_Trigger], list[str], list[str]]:
        """Skill stops named by their responses, starts, invariant failures, stops without a response."""
        stops: list[_Trigger] = []
        starts: list[_Trigger] = []
        cascade: list[str] = []
        unexplained: list[str] = []
        for k, now in st.skills.items():
            before = prev.skills.get(k, SkillView(READY, ""))
            was, running = before.state != READY, now.state != READY
            if was and (not running or now.id != before.id):
                r = self._take(k, before.id)
                self._remember((k, before.id))
                if r is None:
                    unexplained.append(f"{k} stopped without a response")
                elif r.result == RESULTS["INVARIANT_FAILURE"]:
                    cascade.append(termination(r))  # fired by the net's priority after the trigger
                else:
                    stops.append(_Trigger((termination(r),), True, termination(r)))
            if running and (not was or now.id != before.id):
                starts.append(_Trigger((f"{k}.start",), True, f"{k}.start"))
            elif not running and not was and now.id != before.id:
                # A new id on a READY skill: a rejected start (the manager keeps the new
                # id), or a start whose own invariant failed at once.
                r = self._take(k, now.id)
                if r is not None:
                    self._remember((k, now.id))
                    starts.append(_Trigger((f"{k}.start",), True, f"{k}.start"))
                    if r.result == RESULTS["INVARIANT_FAILURE"]:
                        cascade.append(termination(r))
        return stops, starts, cascade, unexplained

    def _event_triggers(self, prev: Status, st: Status) -> list[_Trigger]:
        """One trigger per successful event response received since the previous status."""
        triggers = []
        for e in self._events:
            name = self._requests.pop(e.id, None)
            if name is not None and name in self._event_names:
                triggers.append(_Trigger((name,), True, name))
            else:
                internal = e.id in (st.info, prev.info)
                what = "internal event" if internal else f"event '{e.id}' ({name or 'request not seen'})"
                triggers.append(_Trigger(self._event_names, False, what))
        self._events.clear()
        return triggers

    # -- helpers --------------------------------------------------------------------

    def _take(self, skill: str, id_: str) -> SkillResponse | None:
        for i, r in enumerate(self._responses):
            if r.skill == skill and r.id == id_:
                return self._responses.pop(i)
        return None

    def _remember(self, key: tuple[str, str]) -> None:
        self._handled[key] = None
        _trim(self._handled)

    def marking(self, st: Status) -> int | None:
        """Net marking of a status, or ``None`` when it names something the model lacks."""
        places = []
        for r in self.skillset.resources:
            state = st.resources.get(r.name, r.initial)
            if state not in r.states:
                return None
            places.append(resource_place(r.name, state))
        if set(st.resources) - {r.name for r in self.skillset.resources}:
            return None
        for k in self.skillset.skills:
            view = st.skills.get(k.name)
            places.append(running_place(k.name) if view and view.state != READY else idle_place(k.name))
        return self.net.marking_of(places)

    def _order(self, prev: Status, st: Status, triggers: list[_Trigger]) -> list[str] | None:
        """Names of ``triggers`` in an order that leads the net from ``prev`` to ``st``.

        Orders are tried from the arrival order on and the first that works is kept.
        An event whose name is not known may take any event name, but only when every
        working order gives it the same one (otherwise the name is ambiguous: ``None``).
        """
        start, goal = self.marking(prev), self.marking(st)
        if start is None or goal is None or len(triggers) > MAX_TRIGGERS:
            return None
        first: list[str] | None = None
        guesses: dict[int, set[str]] = {i: set() for i, t in enumerate(triggers) if not t.known}
        found = 0
        for perm in permutations(range(len(triggers))):
            for names in self._paths(start, goal, [triggers[i] for i in perm]):
                first = first or names
                for pos, i in enumerate(perm):
                    if i in guesses:
                        guesses[i].add(names[pos])
                found += 1
                if found >= MAX_SOLUTIONS or not guesses:
                    break
            if first is not None and (found >= MAX_SOLUTIONS or not guesses):
                break
        if first is None or any(len(g) > 1 for g in guesses.values()):
            return None
        return first

    def _event_explains(self, prev: Status, st: Status) -> bool:
        start, goal = self.marking(prev), self.marking(st)
        if start is None or goal is None:
            return False
        return any(True for _ in self._paths(start, goal, [_Trigger(self._event_names, False, "event")]))

    def _paths(self, marking: int, goal: int, todo: list[_Trigger]):
        """Name sequences firing ``todo`` in order from ``marking`` to ``goal`` (depth first)."""
        if not todo:
            if marking == goal:
                yield []
            return
        for name in todo[0].names:
            for t in enabled(self.net, marking):
                if t.name != name:
                    continue
                for m in stable_successors(self.net, marking, t):
                    for rest in self._paths(m, goal, todo[1:]):
                        yield [name, *rest]


def _trim(d: OrderedDict) -> None:
    while len(d) > MAX_REMEMBERED:
        d.popitem(last=False)


__all__ = [
    "Derived", "Deriver", "EventRequest", "EventResponse", "Output", "SkillResponse", "SkillView", "Status",
    "event_request_from_plain", "event_response_from_plain", "skill_response_from_plain", "status_from_plain",
    "termination",
]
