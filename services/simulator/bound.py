"""Simulated ROS 2 action servers, lifecycle nodes and topics of bound skillsets, on Zenoh (docs/semantics.md §9).

The simulator's action-server mode: for a skillset with a binding instead of a
skillset manager, :class:`BoundSimulator` plays the robot's own interfaces, speaking
the real protocols with CDR payloads on the keys of :class:`~skinet.ros.keys.KeyStyle`
(as ``zenoh-bridge-ros2dds`` or ``rmw_zenoh`` carry them):

- per bound skill, an action server: queryables ``<action>/_action/send_goal``,
  ``cancel_goal`` and ``get_result``; ``<action>/_action/status`` (``GoalStatusArray``,
  transient local: an advanced publisher keeping its last sample, as both gateways do)
  and ``feedback``.  A goal is accepted (status ACCEPTED then EXECUTING, one feedback),
  ends when the scenario says (SUCCEEDED or ABORTED with the step's result fields),
  and a cancel request makes it CANCELING then CANCELED at once; a ``get_result`` for
  an active goal is answered when it ends.  ``status_first`` publishes the status
  before the reply to ``send_goal`` (the race a client must stand);
- per lifecycle resource, a lifecycle node: ``<node>/get_state``, ``<node>/change_state``
  (a transition from the node's state succeeds, others answer ``success`` false) and
  ``<node>/transition_event`` through the transition states (configuring, ...);
- every bound topic, published with the step's ``message`` fields.

It announces its servers as the gateways do (``zenoh-bridge-ros2dds``: the route's
``AS`` liveliness token of an action server, ``SS`` of a lifecycle node's
``get_state`` service; ``rmw_zenoh``: node, service and publisher tokens with type
hashes).  :meth:`BoundSimulator.restart_server` and :meth:`~BoundSimulator.restart_node`
restart one action server (it forgets its goals and its status cache) or one
lifecycle node (back to unconfigured), their route tokens leaving and coming back
(``zenoh-bridge-ros2dds`` keys).  :meth:`drive` plays a scenario: ``k.start`` sends a goal as an
operator's client would, ``k.interrupt`` cancels it, outcomes end it, an event
publishes the message that makes its binding fire (a bound event's topic, or the
resource its effects set: a topic sample or a lifecycle transition).  Without a
scenario (a pilot acting through the bindings), ``on_start`` hooks hear of each goal
an action server accepts, and :meth:`~BoundSimulator.terminate` ends it, as the
robot's implementation would.
"""

from __future__ import annotations

import logging
import math
import os
import time
import uuid
from collections.abc import Callable, Mapping
from typing import Any

import zenoh
import zenoh.ext as zext

from services.common.ros_client import ServiceClient
from services.common.ros_liveliness import declare_node
from services.common.zenoh_config import undeclare
from services.simulator.driver import StepRun
from skinet.mission.scenario import Scenario, step_numbers
from services.simulator.protocols import ABORTED, SUCCEEDED, ActionLogic, LifecycleLogic
from skinet.ros.actions import cancel_goal_request, message, send_goal_reply, send_goal_request
from skinet.ros.binding import (
    CANCEL_TYPE, CHANGE_STATE_TYPE, GET_STATE_TYPE, STATUS_TYPE, TRANSITION_EVENT_TYPE, Binding, ResourceBinding, SkillBinding,
    result_fields,
)
from skinet.ros.bound import goal_text
from skinet.ros.keys import KeyStyle, rmw_attachment
from skinet.ros.typestore import encode
from skinet.system.model import System

log = logging.getLogger("skinet.simulator")

class _Publisher:
    """One output topic: CDR payloads, rmw_zenoh attachments, a count of messages published."""

    def __init__(self, sim: "BoundSimulator", key: str, advanced: bool):
        self.sim = sim
        if advanced:  # transient local: the last sample stays in a cache late subscribers read
            self.pub: Any = zext.declare_advanced_publisher(
                sim.session, key, cache=zext.CacheConfig(1), publisher_detection=True,
                sample_miss_detection=zext.MissDetectionConfig())
        else:
            self.pub = sim.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        self.gid, self.sequence, self.count = os.urandom(16), 0, 0

    def put(self, payload: bytes) -> None:
        attachment = None
        if self.sim.style.rmw_zenoh:
            self.sequence += 1
            attachment = rmw_attachment(self.sequence, time.time_ns(), self.gid)
        self.pub.put(payload, attachment=attachment)
        self.count += 1


class _ActionServer:
    """An action server on Zenoh keys: queryables for its services, publishers for status and feedback."""

    def __init__(self, sim: "BoundSimulator", binding: Binding, skill: SkillBinding):
        self.sim, self.skill, self.store, self.skillset = sim, skill, binding.store, binding.skillset
        self.logic = ActionLogic(binding.store, skill.type)
        self.out = {"status": sim.publisher(skill.name("status"), STATUS_TYPE, self.store, advanced=True),
                    "feedback": sim.publisher(skill.name("feedback"), f"{skill.type}_FeedbackMessage", self.store)}
        key = sim.key
        self.queryables = [
            sim.session.declare_queryable(key(skill.name("send_goal"), f"{skill.type}_SendGoal", self.store),
                                          self._send_goal),
            sim.session.declare_queryable(key(skill.name("cancel_goal"), CANCEL_TYPE, self.store), self._cancel),
            sim.session.declare_queryable(key(skill.name("get_result"), f"{skill.type}_GetResult", self.store),
                                          self._get_result),
        ]

    def _reply(self, query: zenoh.Query, payload: bytes) -> None:
        with query:
            query.reply(query.key_expr, payload, attachment=self.sim.reply_attachment(query))

    def _send(self, outputs: list[tuple[str, bytes]], due: list[tuple[Any, bytes]] = ()) -> None:  # type: ignore[assignment]
        for topic, payload in outputs:
            self.out[topic].put(payload)
        for query, payload in due:
            self._reply(query, payload)

    def _send_goal(self, query: zenoh.Query) -> None:
        with self.logic.lock:
            done = self.logic.send_goal(query.payload.to_bytes())
            if done is None:
                query.drop()
                return
            reply, outputs = done
            if outputs:  # accepted: the robot's implementation runs it (told before the client hears of it)
                goal = self.logic.received[-1][0]
                for hook in self.sim.on_start:
                    hook(self.skillset, self.skill.skill, goal_text(goal))
            if not self.sim.status_first:
                self._reply(query, reply)
            self._send(outputs)
            if self.sim.status_first:  # the status overtakes the reply (each has its own route)
                self._reply(query, reply)

    def _cancel(self, query: zenoh.Query) -> None:
        with self.logic.lock:
            done = self.logic.cancel(query.payload.to_bytes())
            if done is None:
                query.drop()
                return
            reply, outputs, due = done
            self._send(outputs[:1])
            self._reply(query, reply)
            self._send(outputs[1:], due)

    def _get_result(self, query: zenoh.Query) -> None:
        with self.logic.lock:
            reply = self.logic.get_result(query.payload.to_bytes(), query)
            if reply is not None:
                self._reply(query, reply)

    def finish(self, status: int, result: Mapping[str, Any], goal_id: bytes | None = None) -> bool:
        with self.logic.lock:
            done = self.logic.finish(status, result, goal_id)
            if done is not None:
                self._send(*done)
            return done is not None

    def close(self) -> None:
        with self.logic.lock:
            for query in self.logic.pending():
                query.drop()
            undeclare(*self.queryables)


class _LifecycleNode:
    def __init__(self, sim: "BoundSimulator", binding: Binding, resource: ResourceBinding, state: int):
        self.sim, self.resource = sim, resource
        self.logic = LifecycleLogic(binding.store, state)
        self.events = sim.publisher(resource.transition_event, TRANSITION_EVENT_TYPE, binding.store)
        self.queryable = sim.session.declare_queryable(sim.key(resource.get_state, GET_STATE_TYPE, binding.store),
                                                       self._get_state)
        self.changes = sim.session.declare_queryable(
            sim.key(resource.change_state, CHANGE_STATE_TYPE, binding.store), self._change_state)

    def _get_state(self, query: zenoh.Query) -> None:
        with query, self.logic.lock:
            query.reply(query.key_expr, self.logic.get_state(), attachment=self.sim.reply_attachment(query))

    def _change_state(self, query: zenoh.Query) -> None:
        """A lifecycle manager's request: the transition, if it starts from the node's state (else success false)."""
        with query:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            with self.logic.lock:
                reply, events = self.logic.change_state(payload)
                for event in events:
                    self.events.put(event)
            query.reply(query.key_expr, reply, attachment=self.sim.reply_attachment(query))

    def transition(self, target: int) -> None:
        """Go to the primary state ``target`` through its transition state, publishing both events."""
        with self.logic.lock:
            for payload in self.logic.transition(target):
                self.events.put(payload)

    def close(self) -> None:
        undeclare(self.queryable, self.changes)


class BoundSimulator:
    """The bound interfaces of every bound skillset of ``system`` on ``session`` (close with :meth:`close`)."""

    def __init__(self, session: zenoh.Session, system: System, bindings: Mapping[str, Binding], *,
                 style: KeyStyle = KeyStyle(), status_first: bool = False):
        self.session = session
        self.system = system
        self.bindings = dict(bindings)
        self.style = style
        self.status_first = status_first
        self.client = ServiceClient(session, style)  # the operator's client (send_goal, cancel_goal)
        # Called with (skillset, skill, goal id as ROS prints it) when an action server accepts a goal, under its
        # lock (the simulated implementations, services.simulator.world.World, end it later): keep them short.
        self.on_start: list[Callable[[str, str, str], None]] = []
        self.publishers: dict[str, _Publisher] = {}  # ROS topic name -> publisher
        self.actions: dict[tuple[str, str], _ActionServer] = {}  # (skillset, skill) -> server
        self.nodes: dict[tuple[str, str], _LifecycleNode] = {}  # (skillset, resource) -> lifecycle node
        self.sent: dict[tuple[str, str], bytes] = {}  # (skillset, skill) -> the goal the operator sent last
        self._tokens: list[Any] = []
        self._routes: dict[str, Any] = {}  # zenoh-bridge-ros2dds: action or service name -> its route token
        entities: list[tuple[str, str, str, str]] = []
        for name, b in self.bindings.items():
            skillset = system.component(name).skillset
            for s in b.skills:
                self.actions[(name, s.skill)] = _ActionServer(self, b, s)
                entities += [("SS", s.name(n), t, self._hash(b, t)) for n, t in (
                    ("send_goal", f"{s.type}_SendGoal"), ("cancel_goal", CANCEL_TYPE),
                    ("get_result", f"{s.type}_GetResult"))]
                entities += [("MP", s.name("status"), STATUS_TYPE, self._hash(b, STATUS_TYPE))]
                self._route("AS", s.action, s.type)
            for r in b.resources:
                if r.lifecycle:
                    initial = dict(r.states).get(skillset.resource(r.resource).initial, 1)
                    self.nodes[(name, r.resource)] = _LifecycleNode(self, b, r, initial)
                    entities += [("SS", r.get_state, GET_STATE_TYPE, self._hash(b, GET_STATE_TYPE)),
                                 ("SS", r.change_state, CHANGE_STATE_TYPE, self._hash(b, CHANGE_STATE_TYPE))]
                    self._route("SS", r.get_state, GET_STATE_TYPE)
                    self._route("SS", r.change_state, CHANGE_STATE_TYPE)
                else:
                    self.publisher(r.topic, r.type, b.store)
            for e in b.events:
                self.publisher(e.topic, e.type, b.store)
        if style.rmw_zenoh and entities:
            _, self._tokens = declare_node(session, style.domain, "/skinet_simulated_robot", entities)  # type: ignore[arg-type]

    def _route(self, kind: str, name: str, typename: str) -> None:
        """zenoh-bridge-ros2dds: the gateway's route token for a DDS action (``AS``) or service (``SS``) server."""
        if not self.style.rmw_zenoh:
            self._routes[name] = self.session.liveliness().declare_token(
                f"@/{self.session.zid()}/@ros2_lv/{kind}/{self.style.name_key(name, '').replace('/', '§')}/"
                f"{typename.replace('/', '§')}")

    def restart_server(self, skillset: str, skill: str) -> None:
        """``skill``'s action server restarts: its goals and status cache are gone, its token leaves and
        comes back (zenoh-bridge-ros2dds keys)."""
        server = self.actions[(skillset, skill)]
        server.close()
        undeclare(self._routes.pop(server.skill.action))
        for topic in ("status", "feedback"):
            undeclare(self.publishers.pop(server.skill.name(topic)).pub)
        self.actions[(skillset, skill)] = _ActionServer(self, self.bindings[skillset], server.skill)
        self._route("AS", server.skill.action, server.skill.type)

    def restart_node(self, skillset: str, resource: str) -> None:
        """``resource``'s lifecycle node restarts, unconfigured: its token leaves and comes back."""
        node = self.nodes[(skillset, resource)]
        node.close()
        undeclare(self._routes.pop(node.resource.get_state), self._routes.pop(node.resource.change_state, None),
                  self.publishers.pop(node.resource.transition_event).pub)
        self.nodes[(skillset, resource)] = _LifecycleNode(self, self.bindings[skillset], node.resource, 1)
        self._route("SS", node.resource.get_state, GET_STATE_TYPE)
        self._route("SS", node.resource.change_state, CHANGE_STATE_TYPE)

    def _hash(self, binding: Binding, typename: str) -> str:
        return self.style.type_hash(binding.store, typename) if binding.store is not None else "*"

    def key(self, name: str, typename: str, store: Any) -> str:
        return self.style.name_key(name, typename, store)

    def publisher(self, topic: str, typename: str, store: Any, advanced: bool = False) -> _Publisher:
        if topic not in self.publishers:
            self.publishers[topic] = _Publisher(self, self.key(topic, typename, store), advanced)
        return self.publishers[topic]

    def reply_attachment(self, query: zenoh.Query) -> bytes | None:
        """rmw_zenoh services answer with the request's attachment (sequence number, client GID)."""
        if not self.style.rmw_zenoh or query.attachment is None:
            return None
        return query.attachment.to_bytes()

    def published(self) -> dict[str, int]:
        """Messages published so far per ROS topic (the bridge has caught up when it has fed as many)."""
        return {t: p.count for t, p in self.publishers.items()}

    # -- the robot's side ---------------------------------------------------------------------

    def finish(self, skillset: str, skill: str, kind: str, result: Mapping[str, Any] | None = None) -> bool:
        """End ``skill``'s active goal: ``kind`` is ``success`` (SUCCEEDED) or ``failure`` (ABORTED)."""
        return self.actions[(skillset, skill)].finish(SUCCEEDED if kind == "success" else ABORTED, result or {})

    def terminate(self, skillset: str, skill: str, kind: str, mode: str = "", id_: str | None = None,
                  result: Mapping[str, Any] | None = None) -> bool:
        """End the goal ``id_`` (as ROS prints it; default: the active one) of ``skill`` in mode ``mode`` of
        ``kind`` (``success``: SUCCEEDED, ``failure``: ABORTED); False when that goal is not active.  Without
        ``result``, the result's fields are those that name ``mode`` through the binding's ``<kind>_when``
        conditions (:func:`~skinet.ros.binding.result_fields`); ValueError when none is found: give them."""
        server = self.actions[(skillset, skill)]
        if result is None:
            result = result_fields(server.skill, kind, mode, self.bindings[skillset].store)
            if result is None:
                outcome = server.skill.success if kind == "success" else server.skill.failure
                raise ValueError(f"{skillset}:{skill}: no result found that names the {kind} mode {mode} (not "
                                 f"the binding's default, {outcome.default}): give the result's fields")
        goal = uuid.UUID(id_).bytes if id_ is not None else None
        return server.finish(SUCCEEDED if kind == "success" else ABORTED, result or {}, goal)

    def publish(self, skillset: str, topic: str, fields: Mapping[str, Any]) -> None:
        """Publish one sample of a bound topic with ``fields`` (others default)."""
        binding = self.bindings[skillset]
        typename = binding.topics()[topic]
        self.publishers[topic].put(encode(binding.store, typename, message(binding.store, typename, fields)))

    def publish_topics(self, topics: Mapping[str, Mapping[str, Any]]) -> None:
        """One sample on each bound topic named (a scenario's ``[scenario] topics``: the robot's first values)."""
        for topic, fields in topics.items():
            skillset = next((n for n, b in self.bindings.items() if topic in b.topics()), None)
            if skillset is None or topic not in self.publishers:
                raise ValueError(f"topic {topic} is bound to no skillset of {self.system.name}")
            self.publish(skillset, topic, fields)

    def lifecycle(self, skillset: str, resource: str, state: str) -> None:
        """Take a lifecycle node to the model state ``state`` of its resource."""
        node = self.nodes[(skillset, resource)]
        node.transition(dict(node.resource.states)[state])

    # -- the operator's client ----------------------------------------------------------------

    def send_goal(self, skillset: str, skill: str, inputs: Mapping[str, Any] | None = None) -> bool:
        """Send a goal as a client would; True when accepted."""
        b, s = self.bindings[skillset], self.actions[(skillset, skill)].skill
        goal = os.urandom(16)
        self.sent[(skillset, skill)] = goal
        reply = self.client.call(s.name("send_goal"), f"{s.type}_SendGoal", send_goal_request(b.store, s.type, goal,
                                                                                               inputs), 5.0)
        with self.actions[(skillset, skill)].logic.lock:  # the server has published what followed its reply
            pass
        return reply is not None and send_goal_reply(b.store, s.type, reply)[0]

    def cancel(self, skillset: str, skill: str) -> bool:
        """Cancel the active goal of ``skill`` as a client would; True when it is canceling."""
        b, server = self.bindings[skillset], self.actions[(skillset, skill)]
        goal = server.logic.current()
        if goal is None:
            return False
        reply = self.client.call(server.skill.name("cancel_goal"), CANCEL_TYPE, cancel_goal_request(b.store, goal.id),
                                 5.0)
        with server.logic.lock:  # the server has published what followed its reply
            pass
        return reply is not None

    # -- scenarios ----------------------------------------------------------------------------

    def play(self, skillset: str, transition: str, fields: Mapping[str, Any] | None) -> bool:
        """Cause ``transition`` of ``skillset`` on the simulated robot; False when it cannot be played."""
        skills = {s.skill for s in self.bindings[skillset].skills}
        head, _, rest = transition.partition(".")
        if head in skills and rest == "start":
            return self.send_goal(skillset, head, fields)
        if head in skills and rest == "interrupt":
            return self.cancel(skillset, head)
        if head in skills and rest.split(".")[0] in ("success", "failure"):
            return self.finish(skillset, head, rest.split(".")[0], fields)
        return self._event(skillset, transition, fields or {})

    def _event(self, skillset: str, event: str, fields: Mapping[str, Any]) -> bool:
        binding = self.bindings[skillset]
        bound = next((e for e in binding.events if e.event == event), None)
        if bound is not None:
            self.publish(skillset, bound.topic, fields)
            return True
        model = self.system.component(skillset).skillset.event(event)
        for effect in model.effects:
            r = next((r for r in binding.resources if r.resource == effect.resource), None)
            if r is not None and r.lifecycle:
                self.lifecycle(skillset, r.resource, effect.state)
                return True
            if r is not None:
                self.publish(skillset, r.topic, fields)
                return True
        raise ValueError(f"event {event} of {skillset} is bound to no interface the simulator can drive")

    def drive(self, scenario: Scenario, speed: float = 1.0,
              on_step: Callable[[StepRun], None] | None = None) -> list[StepRun]:
        """Play ``scenario`` at ``t / speed`` (``speed <= 0``: at once), reporting each step to ``on_step``."""
        runs: list[StepRun] = []
        start = time.monotonic()
        for index, step in zip(step_numbers(scenario), scenario.steps):
            if speed > 0 and math.isfinite(step.t / speed):
                delay = start + step.t / speed - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            if step.transition is None:
                run = StepRun(index, step, "consider", True)
            else:
                ok = self.play(step.skillset, step.transition, step.message)
                if not ok:
                    log.info("step %d: %s:%s had no effect on the simulated robot", index, step.skillset,
                             step.transition)
                head, _, rest = step.transition.partition(".")
                kind = rest.split(".")[0] if rest else "event"
                goal = self.sent.get((step.skillset, head))
                detail = f"goal {goal.hex()}" if kind == "start" and goal else ""
                run = StepRun(index, step, kind, ok, detail)  # type: ignore[arg-type]
            runs.append(run)
            if on_step is not None:
                on_step(run)
        return runs

    def close(self) -> None:
        for server in self.actions.values():
            server.close()
        for node in self.nodes.values():
            node.close()
        undeclare(*self._tokens, *self._routes.values(), *(p.pub for p in self.publishers.values()))


__all__ = ["BoundSimulator"]
