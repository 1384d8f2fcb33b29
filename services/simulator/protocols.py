"""The ROS 2 action and lifecycle protocols as a simulated robot serves them, whatever carries them (docs/semantics.md §9).

:class:`ActionLogic` is one action server's goals, as ``rclcpp_action`` keeps them:
CDR requests in (``send_goal``, ``cancel_goal``, ``get_result``), CDR replies and
``GoalStatusArray`` / feedback messages out.  Every goal received is kept
(``received``: its id and fields); while ``accepting`` is false, goals are rejected
(``accepted`` false, no status), as a server whose goal callback refuses them.  A goal is accepted (status ACCEPTED,
then EXECUTING, one feedback message), ends when the robot says so (SUCCEEDED or
ABORTED with a result), and a cancel request makes it CANCELING then CANCELED at
once; a ``get_result`` for an active goal is answered when it ends.
:class:`LifecycleLogic` is one lifecycle node: ``get_state``, ``change_state`` (a
transition that starts from the node's primary state succeeds; another answers
``success`` false and changes nothing) and the ``TransitionEvent`` pairs through a
transition state (configuring, activating, ...).

The transports (:mod:`services.simulator.bound` on Zenoh keys,
:mod:`services.simulator.dds_bound` on DDS) only move the bytes.  Not thread-safe:
callers hold ``lock``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from skinet.ros.actions import LIFECYCLE_TRANSITIONS, goal_uuid, message
from skinet.ros.binding import CANCEL_TYPE, CHANGE_STATE_TYPE, GET_STATE_TYPE, LIFECYCLE_STATES, STATUS_TYPE, TRANSITION_EVENT_TYPE
from skinet.ros.stamp import ros_time
from skinet.ros.typestore import decode, default_instance, encode, to_plain

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

log = logging.getLogger("skinet.simulator")

ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = 1, 2, 3, 4, 5, 6
ACTIVE = (ACCEPTED, EXECUTING, CANCELING)
# lifecycle: (from, to) primary states -> the transition state between them
TRANSITION_STATES = {(1, 2): 10, (2, 1): 11, (2, 3): 13, (3, 2): 14}
SHUTTING_DOWN, ERROR_PROCESSING = 12, 15
LABELS = {v: k for k, v in LIFECYCLE_STATES.items()} | {10: "configuring", 11: "cleaningup", 12: "shuttingdown",
                                                       13: "activating", 14: "deactivating", 15: "errorprocessing"}

Output = tuple[str, bytes]  # ("status" | "feedback", CDR)


@dataclass
class Goal:
    id: bytes
    stamp: float
    status: int = ACCEPTED
    result: dict[str, Any] = field(default_factory=dict)
    waiting: list[Any] = field(default_factory=list)  # the transport's pending get_result requests


class ActionLogic:
    """The goals of one action server of type ``action`` (``nav2_msgs/action/NavigateToPose``)."""

    def __init__(self, store: Typestore, action: str):
        self.store = store
        self.action = action
        self.goals: OrderedDict[bytes, Goal] = OrderedDict()
        self.received: list[tuple[bytes, dict[str, Any]]] = []  # every goal sent to it: (id, fields), in order
        self.accepting = True
        self.lock = threading.Lock()

    def current(self) -> Goal | None:
        """The latest active goal."""
        return next((g for g in reversed(self.goals.values()) if g.status in ACTIVE), None)

    def status_array(self) -> bytes:
        items = []
        for g in self.goals.values():
            sec, nanosec, _ = ros_time(g.stamp)  # clamped past 2038: said when the goal came
            info = default_instance(self.store, "action_msgs/msg/GoalInfo", goal_id=goal_uuid(self.store, g.id),
                                    stamp=default_instance(self.store, "builtin_interfaces/msg/Time", sec=sec,
                                                           nanosec=nanosec))
            items.append(default_instance(self.store, "action_msgs/msg/GoalStatus", goal_info=info, status=g.status))
        return encode(self.store, STATUS_TYPE, default_instance(self.store, STATUS_TYPE, status_list=items))

    def send_goal(self, payload: bytes) -> tuple[bytes, list[Output]] | None:
        """(reply, outputs) for a ``SendGoal`` request; ``None`` when it does not decode."""
        try:
            request = decode(self.store, f"{self.action}_SendGoal_Request", payload)
        except Exception as exc:  # never crash on a bad request (docs/semantics.md §7)
            log.warning("%s: bad send_goal request ignored: %s", self.action, exc)
            return None
        goal = Goal(bytes(request.goal_id.uuid), time.time())
        self.received.append((goal.id, to_plain(request.goal)))
        typename = f"{self.action}_SendGoal_Response"
        sec, nanosec, problem = ros_time(goal.stamp)
        if problem:
            log.warning("%s: goal accepted with %s", self.action, problem)
        reply = encode(self.store, typename, default_instance(
            self.store, typename, accepted=self.accepting,
            stamp=default_instance(self.store, "builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)))
        if not self.accepting:
            return reply, []
        self.goals[goal.id] = goal
        outputs = [("status", self.status_array())]  # ACCEPTED
        goal.status = EXECUTING
        feedback = default_instance(self.store, f"{self.action}_FeedbackMessage",
                                    goal_id=goal_uuid(self.store, goal.id))
        outputs += [("status", self.status_array()),
                    ("feedback", encode(self.store, f"{self.action}_FeedbackMessage", feedback))]
        return reply, outputs

    def cancel(self, payload: bytes) -> tuple[bytes, list[Output], list[tuple[Any, bytes]]] | None:
        """(reply, outputs, get_result replies now due) for a ``CancelGoal`` request of one goal id."""
        try:
            request = decode(self.store, f"{CANCEL_TYPE}_Request", payload)
        except Exception as exc:
            log.warning("%s: bad cancel_goal request ignored: %s", self.action, exc)
            return None
        goal = self.goals.get(bytes(request.goal_info.goal_id.uuid))
        canceling, outputs, due = [], [], []
        if goal is not None and goal.status in (ACCEPTED, EXECUTING):
            goal.status = CANCELING
            outputs.append(("status", self.status_array()))
            canceling.append(default_instance(self.store, "action_msgs/msg/GoalInfo",
                                              goal_id=goal_uuid(self.store, goal.id)))
        code = 0 if canceling else 2 if goal is None else 3  # ERROR_NONE, UNKNOWN_GOAL_ID, GOAL_TERMINATED
        reply = encode(self.store, f"{CANCEL_TYPE}_Response", default_instance(
            self.store, f"{CANCEL_TYPE}_Response", return_code=code, goals_canceling=canceling))
        if goal is not None and canceling:  # the implementation stops at once
            more, due = self._end(goal, CANCELED, {})
            outputs += more
        return reply, outputs, due

    def get_result(self, payload: bytes, token: Any) -> bytes | None:
        """The reply to a ``GetResult`` request now, or ``None``: ``token`` is answered when the goal ends."""
        try:
            request = decode(self.store, f"{self.action}_GetResult_Request", payload)
        except Exception as exc:
            log.warning("%s: bad get_result request ignored: %s", self.action, exc)
            return self.result_reply(0, {})
        goal = self.goals.get(bytes(request.goal_id.uuid))
        if goal is None:
            return self.result_reply(0, {})
        if goal.status in ACTIVE:
            goal.waiting.append(token)
            return None
        return self.result_reply(goal.status, goal.result)

    def result_reply(self, status: int, result: Mapping[str, Any]) -> bytes:
        typename = f"{self.action}_GetResult_Response"
        return encode(self.store, typename, default_instance(
            self.store, typename, status=status, result=message(self.store, f"{self.action}_Result", result)))

    def _end(self, goal: Goal, status: int, result: Mapping[str, Any]) -> tuple[list[Output], list[tuple[Any, bytes]]]:
        goal.status, goal.result = status, dict(result)
        due = [(token, self.result_reply(status, result)) for token in goal.waiting]
        goal.waiting.clear()
        return [("status", self.status_array())], due

    def finish(self, status: int, result: Mapping[str, Any],
               goal_id: bytes | None = None) -> tuple[list[Output], list[tuple[Any, bytes]]] | None:
        """End the latest active goal, or the goal ``goal_id`` (SUCCEEDED or ABORTED); ``None`` when it is not
        active.

        An unknown result field raises ``TypeError`` (with the fields the result has)."""
        goal = self.current() if goal_id is None else self.goals.get(goal_id)
        if goal is None or goal.status not in ACTIVE:
            return None
        message(self.store, f"{self.action}_Result", result)
        return self._end(goal, status, result)

    def pending(self) -> list[Any]:
        """Every get_result request still waiting (to drop them at close)."""
        out = [t for g in self.goals.values() for t in g.waiting]
        for g in self.goals.values():
            g.waiting.clear()
        return out


class LifecycleLogic:
    """One lifecycle node in the primary state ``state`` (lifecycle_msgs/msg/State ids)."""

    def __init__(self, store: Typestore, state: int):
        self.store = store
        self.state = state
        self.lock = threading.Lock()

    def _state(self, state_id: int) -> Any:
        return default_instance(self.store, "lifecycle_msgs/msg/State", id=state_id, label=LABELS.get(state_id, ""))

    def get_state(self) -> bytes:
        typename = f"{GET_STATE_TYPE}_Response"
        return encode(self.store, typename, default_instance(self.store, typename,
                                                             current_state=self._state(self.state)))

    def change_state(self, request: bytes) -> tuple[bytes, list[bytes]]:
        """The reply to a ``ChangeState`` request, and the transition events it causes (none when it fails)."""
        try:
            transition = int(decode(self.store, f"{CHANGE_STATE_TYPE}_Request", request).transition.id)
        except Exception as exc:  # a malformed request: refused, logged, the node stays as it is
            log.warning("change_state: a request that does not decode: %s", exc)
            transition = -1
        target = next((t for (s, t), (i, _) in LIFECYCLE_TRANSITIONS.items() if s == self.state and i == transition),
                      None)
        events = self.transition(target) if target is not None else []
        typename = f"{CHANGE_STATE_TYPE}_Response"
        return encode(self.store, typename, default_instance(self.store, typename, success=target is not None)), events

    def transition(self, target: int) -> list[bytes]:
        """The two ``TransitionEvent`` messages taking the node to the primary state ``target``."""
        middle = TRANSITION_STATES.get((self.state, target), SHUTTING_DOWN if target == 4 else ERROR_PROCESSING)
        out = []
        for start, goal in ((self.state, middle), (middle, target)):
            msg = default_instance(self.store, TRANSITION_EVENT_TYPE, timestamp=time.time_ns(),
                                   start_state=self._state(start), goal_state=self._state(goal))
            out.append(encode(self.store, TRANSITION_EVENT_TYPE, msg))
        self.state = target
        return out


__all__ = ["ABORTED", "ACTIVE", "ActionLogic", "CANCELED", "Goal", "LifecycleLogic", "SUCCEEDED"]
