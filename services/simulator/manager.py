"""The semantics of one generated skillset manager, without I/O (corpus README).

Follows ONERA's generated C++ manager (``Skill.cpp``, ``Event.cpp`` of the corpus's
origin repository):

- a skill request on a running or interrupting skill is answered ALREADY_RUNNING
  with the running execution's id; otherwise the new id and input are kept even
  when the start is then rejected: PRECONDITION_FAILURE (one bool per
  precondition), START_FAILURE (start effects illegal); a successful start gets
  no response, only the status showing the skill RUNNING;
- after every change the invariants of every running skill are checked until
  nothing changes: every violated invariant applies its effects (when legal), the
  skill stops and its response (INVARIANT_FAILURE) names the last violated one;
- an interrupt with the running id stops the skill (INTERRUPT) or, with
  ``interrupting true``, puts it in INTERRUPTING until the implementation is done;
- events: GUARD_FAILURE, EFFECT_FAILURE, UNDEFINED (unknown name) or SUCCESS;
  events raised by the implementation itself answer with ``id`` = status ``info``;
- terminations (success/failure modes) answer SUCCESS/FAILURE with ``name`` =
  mode, ``effect`` (effects applied) and ``postcondition``.

Every handled input publishes the status, after the responses.  Effect sets are
applied whole or not at all (docs/semantics.md §3).  The simulated *world* makes a mode's or an
interrupt's postcondition true when the skill ends (as the net's transition does,
docs/semantics.md §3 *Postconditions*), so ``postcondition`` is true unless unsatisfiable.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from skinet.lang.dnf import dnf
from skinet.lang.expr import Expr, holds
from skinet.lang.model import Effect, Mode, Skill, Skillset
from skinet.ros.interfaces import (
    EVENT_RESULTS, RESULTS, SKILL_STATES, event_response_topic, skill_topic, skill_type, status_field, status_topic,
)
from skinet.ros.stamp import ros_time
from skinet.ros.typestore import default_instance, msg_typename

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

READY, RUNNING, INTERRUPTING = (SKILL_STATES[s] for s in ("READY", "RUNNING", "INTERRUPTING"))

log = logging.getLogger("skinet.simulator")


@dataclass(frozen=True)
class Message:
    """A message the manager publishes: node-relative topic, full type name, rosbags object."""

    topic: str
    typename: str
    msg: Any


@dataclass
class _SkillState:
    state: int
    id: str
    input: Any


class Manager:
    """One skillset manager: each input returns the messages to publish, in order."""

    def __init__(self, skillset: Skillset, store: Typestore, info: str = "", clock: Callable[[], float] = time.time):
        self.skillset = skillset
        self.store = store
        self.info = info
        self.clock = clock
        self.clamped = 0  # status stamps outside ROS Time's int32 seconds, sent clamped (logged once)
        self.resources = {r.name: r.initial for r in skillset.resources}
        self.skills = {
            k.name: _SkillState(READY, "", default_instance(store, self._type(skill_type(k, "Input"))))
            for k in skillset.skills
        }
        self._states = {r.name: r.states for r in skillset.resources}
        self.status_topic = status_topic(skillset)

    # -- inputs from the ROS side ---------------------------------------------------------

    def status_request(self) -> list[Message]:
        return [self.status()]

    def skill_request(self, skill: str, id_: str, input_: Any = None) -> list[Message]:
        k = self.skillset.skill(skill)
        s = self.skills[skill]
        if s.state != READY:
            return [self._response(k, "ALREADY_RUNNING"), self.status()]
        s.id = id_
        if input_ is not None:
            s.input = input_
        checks = {p.name: holds(p.expr, self.resources) for p in k.preconditions}
        if not all(checks.values()):
            return [self._response(k, "PRECONDITION_FAILURE", preconditions=checks), self.status()]
        if not self._legal(k.start):
            return [self._response(k, "START_FAILURE", preconditions=checks), self.status()]
        self._apply(k.start)
        s.state = RUNNING
        return [*self._invariants(), self.status()]

    def interrupt(self, skill: str, id_: str) -> list[Message]:
        """SkillInterrupt: ignored unless ``id_`` is the running execution's (as the manager does)."""
        k = self.skillset.skill(skill)
        s = self.skills[skill]
        if s.id != id_ or s.state != RUNNING:
            return []
        if k.interrupt.interrupting:
            s.state = INTERRUPTING
            return [self.status()]
        return self._stop(k, "INTERRUPT", "", k.interrupt.effects, k.interrupt.postcondition)

    def event_request(self, id_: str, name: str) -> list[Message]:
        names = {e.name for e in self.skillset.events}
        code, cascade = self._event(name) if name in names else ("UNDEFINED", [])
        response = self._message(event_response_topic(self.skillset), "EventResponse",
                                 id=id_, response=EVENT_RESULTS[code])
        return [*cascade, response, self.status()]

    # -- the skill implementations (simulated) --------------------------------------------

    def interrupted(self, skill: str) -> list[Message]:
        """The implementation has finished interrupting ``skill`` (INTERRUPTING -> READY)."""
        k = self.skillset.skill(skill)
        if self.skills[skill].state != INTERRUPTING:
            return []
        return self._stop(k, "INTERRUPT", "", k.interrupt.effects, k.interrupt.postcondition)

    def terminate(self, skill: str, kind: str, mode: str = "") -> list[Message]:
        """End a RUNNING skill in a success or failure mode; ``[]`` when it is not running."""
        k = self.skillset.skill(skill)
        m = _mode(k, kind, mode)
        if self.skills[skill].state != RUNNING:
            return []
        return self._stop(k, "SUCCESS" if kind == "success" else "FAILURE", m.name, m.effects, m.postcondition)

    def raise_event(self, name: str) -> list[Message]:
        """An event raised by the implementation: the response id is the status ``info``."""
        return self.event_request(self.info, name)

    # -- status and responses -------------------------------------------------------------

    def status(self) -> Message:
        sec, nanosec, problem = ros_time(self.clock())
        if problem:
            self.clamped += 1
            if self.clamped == 1:
                log.warning("%s: %s (and every later one like it)", self.skillset.name, problem)
        stamp = default_instance(self.store, "builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)
        resources = [
            default_instance(self.store, self._type("ResourceState"), name=r, state=s)
            for r, s in self.resources.items()
        ]
        skills = {
            status_field(k): default_instance(
                self.store, self._type(skill_type(k, "Status")),
                name=k.name, id=self.skills[k.name].id, state=self.skills[k.name].state, input=self.skills[k.name].input,
            )
            for k in self.skillset.skills
        }
        return self._message(status_topic(self.skillset), "SkillsetStatus", stamp=stamp, resources=resources,
                             info=self.info, **skills)

    def _response(self, k: Skill, result: str, name: str = "", effect: bool = False, postcondition: bool = True,
                  preconditions: dict[str, bool] | None = None) -> Message:
        from rosbags.typesys.base import normalize_fieldname

        pre = {p.name: True for p in k.preconditions} | (preconditions or {})
        return self._message(
            skill_topic(self.skillset, k, "response"), skill_type(k, "Response"),
            id=self.skills[k.name].id, result=RESULTS[result], name=name, effect=effect, postcondition=postcondition,
            **{normalize_fieldname(p): v for p, v in pre.items()},
        )

    def _message(self, topic: str, message: str, **values: Any) -> Message:
        typename = self._type(message)
        return Message(topic, typename, default_instance(self.store, typename, **values))

    def _type(self, message: str) -> str:
        return msg_typename(self.skillset, message)

    # -- semantics ------------------------------------------------------------------------

    def _legal(self, effects: Iterable[Effect]) -> bool:
        return all(self.skillset.resource(e.resource).allows(self.resources[e.resource], e.state) for e in effects)

    def _apply(self, effects: Iterable[Effect]) -> None:
        for e in effects:
            self.resources[e.resource] = e.state

    def _try_effects(self, effects: tuple[Effect, ...]) -> bool:
        """Apply a whole effect set if every move is legal; True when something was applied."""
        if not effects or not self._legal(effects):
            return False
        self._apply(effects)
        return True

    def _make_true(self, post: Expr | None) -> bool:
        """The world makes ``post`` true (first DNF clause, no legality check); its final truth."""
        if not holds(post, self.resources):
            clauses = dnf(post, self._states)
            if clauses:
                self.resources.update(clauses[0])
        return holds(post, self.resources)

    def _stop(self, k: Skill, result: str, name: str, effects: tuple[Effect, ...], post: Expr | None) -> list[Message]:
        self.skills[k.name].state = READY
        effect = self._try_effects(effects)
        postcondition = self._make_true(post)
        cascade = self._invariants()
        return [*cascade, self._response(k, result, name, effect, postcondition), self.status()]

    def _event(self, name: str) -> tuple[str, list[Message]]:
        e = self.skillset.event(name)
        if not holds(e.guard, self.resources):
            return "GUARD_FAILURE", []
        if not self._legal(e.effects):
            return "EFFECT_FAILURE", []
        self._apply(e.effects)
        return "SUCCESS", self._invariants()

    def _invariants(self) -> list[Message]:
        """Invariant checks of every running skill until no failure applies an effect."""
        out: list[Message] = []
        again = True
        while again:
            again = False
            for k in self.skillset.skills:
                if self.skills[k.name].state == READY:
                    continue
                violated, effect = "", False
                for inv in k.invariants:
                    if not holds(inv.guard, self.resources):
                        violated = inv.name
                        effect = self._try_effects(inv.effects) or effect
                if violated:
                    self.skills[k.name].state = READY
                    again = again or effect
                    out.append(self._response(k, "INVARIANT_FAILURE", violated, effect))
        return out


def _mode(k: Skill, kind: str, name: str) -> Mode:
    if kind not in ("success", "failure"):
        raise ValueError(f"mode kind must be 'success' or 'failure', not '{kind}'")
    for m in k.modes:
        if m.kind == kind and m.name == name:
            return m
    known = ", ".join(f"{m.kind}.{m.name}" if m.name else m.kind for m in k.modes) or "none"
    raise ValueError(f"skill '{k.name}' has no {kind} mode '{name}' (modes: {known})")


__all__ = ["INTERRUPTING", "READY", "RUNNING", "Manager", "Message", "holds"]
