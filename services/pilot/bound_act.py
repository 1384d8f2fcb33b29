"""The pilot's commands for skills bound to ROS 2 actions (docs/semantics.md §9, *Acting*): goals and cancel requests.

For a skill whose skillset has a binding instead of a skillset manager
(:mod:`skinet.ros.binding`), :class:`BoundActuator` does what an action client does,
on the keys of :class:`~skinet.ros.keys.KeyStyle` (``zenoh-bridge-ros2dds`` or
``rmw_zenoh``, as the bound bridge reads them):

- ``SKILL.start``: a ``send_goal`` request on ``<action>/_action/send_goal`` with a
  new goal id (UUID 4) and the goal's fields from the command's inputs, as the
  binding maps them (:meth:`~skinet.ros.binding.SkillBinding.goal_fields`: its fixed
  ``goal`` fields, each input at its field).  A goal the server rejects
  (``accepted`` false) raises :class:`~services.pilot.errors.Refused` (nothing changed:
  the pilot asks again, up to its ``max_retries``); no reply within ``timeout``, or a
  reply that does not decode, :class:`~services.pilot.errors.ActError`.
- ``SKILL.interrupt``: a ``cancel_goal`` request for one goal id: the goal this
  actuator sent and the server accepted, unless the action's status shows it ended; otherwise (the operator
  started the skill) the goal the bridge follows, read from the status cache
  (:func:`~skinet.ros.actions.followed_goal`).  No active goal raises
  :class:`ActError`; a cancel the server refuses (``ERROR_REJECTED``,
  ``ERROR_UNKNOWN_GOAL_ID``, ``ERROR_GOAL_TERMINATED``) :class:`Refused`, with its code.

- an event the binding commands (docs/robot.md, *Commanded resources*): the resource it
  changes is a lifecycle node's, so the actuator asks the node its state (``get_state``)
  and calls ``<node>/change_state`` (``lifecycle_msgs/srv/ChangeState``) with the
  transition that leads to the primary state the event's effect maps to
  (:func:`~skinet.ros.actions.lifecycle_transition`); a reply with ``success`` false is a
  :class:`Refused`.  A commanded topic resource gets one message on its topic: the
  value its binding's condition for the target state makes unique
  (:func:`~skinet.ros.condition.unique_message`); a condition that names no single value
  raises :class:`ActError`, for the command cannot be sent.

On ``rmw_zenoh`` keys the actuator shows in the ROS graph as rmw_zenoh clients do: a
node ``/skinet_pilot_<n>`` with a service client token for each action's
``send_goal`` and ``cancel_goal``.  What a start or an interrupt caused is not this
module's business: the bridge sees it in the action's status and the pilot in the
monitor's live state.  Each command
is one request and one reply (an interrupt: one read of the status cache more).
"""

from __future__ import annotations

import itertools
import json
import uuid
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import zenoh

from services.common.ros_client import ServiceClient
from services.common.ros_liveliness import declare_node
from services.common.zenoh_config import undeclare
from services.pilot.errors import ActError, Refused
from skinet.lang.dnf import dnf
from skinet.lang.model import Skillset
from skinet.ros.actions import (
    SentGoal, cancel_goal_reply, cancel_goal_request, change_state_reply, change_state_request, followed_goal,
    get_state_reply, get_state_request, lifecycle_transition, message, send_goal_reply, send_goal_request,
)
from skinet.ros.binding import (
    CANCEL_TYPE, CHANGE_STATE_TYPE, GET_STATE_TYPE, LIFECYCLE_STATES, STATUS_TYPE, Binding, ResourceBinding,
    SkillBinding, bound_inputs_problem,
)
from skinet.ros.condition import unique_message
from skinet.ros.bound import STATUS_NAMES, Goal, goal_text, goals_from_plain
from skinet.ros.keys import KeyStyle, history_selector
from skinet.ros.typestore import decode, encode, to_plain
from skinet.wire.messages import PilotCommand


T = TypeVar("T")
_nodes = itertools.count(1)  # node names of the actuators of this process


class BoundActuator:
    """Sends the pilot's commands to the action servers of the bound skillsets ``bindings`` (skillset name ->
    its binding) through ``session``; ``timeout``: seconds to wait for a server's reply; ``skillsets``: the models
    (skillset name -> :class:`~skinet.lang.model.Skillset`), for the effects of the events a binding commands."""

    def __init__(self, session: zenoh.Session, bindings: Mapping[str, Binding], *, style: KeyStyle = KeyStyle(),
                 timeout: float = 5.0, skillsets: Mapping[str, Skillset] | None = None):
        self.session = session
        self.bindings = dict(bindings)
        self.skillsets = dict(skillsets or {})
        self.style = style
        self.timeout = timeout
        self.client = ServiceClient(session, style)
        self.sent: dict[tuple[str, str], SentGoal] = {}  # (skillset, skill) -> the last goal sent
        self._tokens: list[Any] = []
        if style.rmw_zenoh:  # an action client in the ROS graph (ros2 node list, ros2 service info), as rmw does
            clients = [("SC", s.name(name), typename, style.type_hash(b.store, typename))
                       for b in self.bindings.values() for s in b.skills
                       for name, typename in (("send_goal", f"{s.type}_SendGoal"), ("cancel_goal", CANCEL_TYPE))]
            _, self._tokens = declare_node(session, style.domain, f"/skinet_pilot_{next(_nodes)}", clients)

    def send(self, command: PilotCommand) -> str:
        """Send ``command`` (``SKILL.start``, ``SKILL.interrupt`` or a commanded event); returns what was sent,
        for the log."""
        skill, _, kind = command.transition.partition(".")
        binding = self.bindings.get(command.skillset)
        if binding is not None and not kind and command.transition in binding.commanded:
            return self._event(command.skillset, binding, command.transition)
        model = self.skillsets.get(command.skillset)
        if binding is not None and not kind and model is not None and any(e.name == skill for e in model.events):
            raise ActError(f"{command.skillset}:{skill} is an event its binding does not command (the robot's own): "
                           "the pilot cannot send it")
        bound = binding.skill(skill) if binding is not None else None
        if binding is None or bound is None:
            raise ActError(f"{command.skillset}:{skill} is bound to no action" + (
                " (its skillset has no manager either: the pilot cannot command it)" if binding else ""))
        if kind == "start":
            return self._start(command.skillset, binding, bound, command.inputs)
        if kind == "interrupt":
            return self._interrupt(command.skillset, binding, bound)
        raise ActError(f"{command.skillset}:{command.transition} is not a command (SKILL.start or SKILL.interrupt)")

    def problem(self, skillset: str, skill: str, inputs: Mapping[str, Any]) -> str | None:
        """Why a start of ``skillset:skill`` with ``inputs`` could not be sent (its goal message), or None; the
        pilot asks when it accepts a goal, before the robot moves for it."""
        return bound_inputs_problem(self.bindings, skillset, skill, inputs)  # not bound: send says why

    def _start(self, skillset: str, binding: Binding, skill: SkillBinding, inputs: Mapping[str, Any]) -> str:
        problem = self.problem(skillset, skill.skill, inputs)
        if problem:
            raise ActError(problem)
        fields = skill.goal_fields(inputs)
        goal = SentGoal(uuid.uuid4().bytes)
        sent = f"send_goal {skill.action} goal {goal_text(goal.id)} {json.dumps(fields, sort_keys=True)}"
        try:
            request = send_goal_request(binding.store, skill.type, goal.id, fields)
        except Exception as exc:  # a value the type check let through that CDR refuses: never crash the pilot
            raise ActError(f"{sent}: cannot be encoded: {exc}") from None
        accepted, _ = self._call(skill.name("send_goal"), f"{skill.type}_SendGoal", request, sent,
                                 f"the action server of {skill.action}", skill.action,
                                 lambda reply: send_goal_reply(binding.store, skill.type, reply))
        goal.on_reply(accepted)
        if not accepted:  # nothing changed on the robot: the pilot may ask again (Refused)
            raise Refused(f"{sent}: the action server of {skill.action} rejected the goal")
        self.sent[(skillset, skill.skill)] = goal
        return f"{sent}: accepted"

    def _interrupt(self, skillset: str, binding: Binding, skill: SkillBinding) -> str:
        goals = self._status(binding, skill)
        own = self.sent.get((skillset, skill.skill))
        if own is not None:
            own.on_status(goals)
        # Its own accepted goal even before a status shows it (the status follows the accept a moment later);
        # one that ended meanwhile gets ERROR_GOAL_TERMINATED, a refusal.
        target = own.id if own is not None and own.accepted and not own.done else None
        whose = "the goal the pilot sent"
        if target is None:
            followed = followed_goal(goals)
            if followed is None:
                raise ActError(f"{skillset}:{skill.skill}: no goal of {skill.action} is active (its status shows "
                               f"{_shown(goals)}): nothing to cancel")
            target, whose = followed.id, "the goal the bridge follows"
        sent = f"cancel_goal {skill.action} goal {goal_text(target)} ({whose})"
        code, canceling = self._call(skill.name("cancel_goal"), CANCEL_TYPE, cancel_goal_request(binding.store, target),
                                     sent, f"the action server of {skill.action}", skill.action,
                                     lambda reply: cancel_goal_reply(binding.store, reply))
        if code != "ERROR_NONE" or target not in canceling:
            raise Refused(f"{sent}: the action server of {skill.action} refused: {code}")
        return f"{sent}: canceling"

    def _event(self, skillset: str, binding: Binding, event: str) -> str:
        """Command ``event``: the change of the commanded resource its effect names, through its interface."""
        model = self.skillsets.get(skillset)
        if model is None:
            raise ActError(f"{skillset}:{event}: this pilot has not the model of {skillset}: it cannot tell what the "
                           "event commands")
        effects = {e.resource: e.state for e in model.event(event).effects}
        rb = next((r for r in binding.resources if r.commanded and r.resource in effects), None)
        if rb is None:
            raise ActError(f"{skillset}:{event} sets no resource that its binding commands: the pilot cannot send it")
        target = effects[rb.resource]
        ev = model.event(event)
        states = {r.name: r.states for r in model.resources}
        sources = {c.get(rb.resource) for c in dnf(ev.guard, states)}
        sources = set(states[rb.resource]) if None in sources else sources  # where the event may happen
        if rb.lifecycle:
            return self._lifecycle(skillset, binding, rb, event, target, sources)
        return self._topic(skillset, binding, rb, event, target)

    def _lifecycle(self, skillset: str, binding: Binding, rb: ResourceBinding, event: str, target: str,
                   sources: set[str]) -> str:
        goal = dict(rb.states).get(target)
        labels = {i: name for name, i in LIFECYCLE_STATES.items()}
        if goal is None:
            raise ActError(f"{skillset}:{event}: state {target} of {rb.resource} is no lifecycle state of "
                           f"{rb.lifecycle}: the pilot cannot command it")
        now, _ = self._call(rb.get_state, GET_STATE_TYPE, get_state_request(binding.store), f"{skillset}:{event}",
                            rb.get_state, rb.get_state, lambda reply: get_state_reply(binding.store, reply))
        state = rb.lifecycle_state(now)
        if state not in sources:  # the node moved since the plan was made: this event is not what it would do now
            raise Refused(f"{skillset}:{event}: {rb.lifecycle} is {labels.get(now, now)}, where {event} cannot "
                          f"happen ({rb.resource} must be {' or '.join(sorted(sources))})")
        transition = lifecycle_transition(now, goal)
        if transition is None:
            raise Refused(f"{skillset}:{event}: {rb.lifecycle} is {labels.get(now, now)}, and no lifecycle "
                          f"transition leads from there to {labels[goal]}")
        number, label = transition
        sent = f"change_state {rb.lifecycle} {label} (transition {number}, {labels.get(now, now)} -> {labels[goal]})"
        request = change_state_request(binding.store, number, label)
        success = self._call(rb.change_state, CHANGE_STATE_TYPE, request, sent, rb.change_state, rb.change_state,
                             lambda reply: change_state_reply(binding.store, reply))
        if not success:
            raise Refused(f"{sent}: {rb.lifecycle} refused the transition")
        return f"{sent}: done"

    def _topic(self, skillset: str, binding: Binding, rb: ResourceBinding, event: str, target: str) -> str:
        condition = dict(rb.states).get(target)
        fields = unique_message(condition, binding.store) if condition is not None else None
        if condition is None or fields is None:
            shown = f"'{condition.text}'" if condition is not None else "no condition"
            raise ActError(f"{skillset}:{event} cannot be sent: the binding maps {rb.resource} {target} to {shown} "
                           f"on {rb.topic}, which names no single message to publish")
        msg = message(binding.store, rb.type, fields)
        plain = to_plain(msg)
        if not condition.holds(plain) or any(c.holds(plain) for s, c in rb.states if s != target):
            raise ActError(f"{skillset}:{event} cannot be sent: no message on {rb.topic} makes {rb.resource} "
                           f"{target} alone")
        payload = encode(binding.store, rb.type, msg)
        self.session.put(self.style.name_key(rb.topic, rb.type, binding.store), payload)
        return f"publish {rb.topic} {json.dumps(fields, sort_keys=True)}"

    def _call(self, name: str, typename: str, payload: bytes, sent: str, server: str, source: str,
              read: Callable[[bytes], T]) -> T:
        """One service call: its reply read by ``read``; no reply or one that does not decode raises :class:`ActError`
        (``sent``: what was asked, ``server``: who must answer, ``source``: whose reply it is, for the reason)."""
        reply = self.client.call(name, typename, payload, self.timeout)
        if reply is None:
            raise ActError(f"{sent}: no reply from {server} within {self.timeout:g} s")
        try:
            return read(reply)
        except Exception as exc:
            raise ActError(f"{sent}: the reply of {source} does not decode: {exc}") from None

    def _status(self, binding: Binding, skill: SkillBinding) -> list[Goal]:
        """The goals of the action's last status (its transient-local cache); none when it never had one."""
        key = history_selector(self.style.name_key(skill.name("status"), STATUS_TYPE))
        goals: list[Goal] = []
        for reply in self.session.get(key, accept_replies=zenoh.ReplyKeyExpr.ANY, timeout=self.timeout):
            if reply.ok is not None:
                try:  # the cache answers oldest first: the last one is the current status
                    goals = goals_from_plain(to_plain(decode(binding.store, STATUS_TYPE, reply.ok.payload.to_bytes())))
                except Exception:  # a malformed status: skipped (the bridge counts it)
                    continue
        return goals

    def close(self) -> None:
        """Leave the ROS graph (rmw_zenoh); the rest is requests only."""
        undeclare(*self._tokens)


def _shown(goals: list[Goal]) -> str:
    return ", ".join(f"{goal_text(g.id)[:8]} {STATUS_NAMES.get(g.status, g.status)}" for g in goals) or "no goal"


__all__ = ["BoundActuator"]
