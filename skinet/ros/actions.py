"""Requests and replies of the ROS 2 action and lifecycle protocols, in CDR (docs/semantics.md §9).

What a client puts on the wire to act through a binding, and reads back:

- :func:`send_goal_request`: ``<action>/_action/send_goal`` with a goal id and the goal's
  fields (the plan's inputs, docs/semantics.md §8: ``SKILL.start``); :func:`send_goal_reply` reads
  the answer (accepted, stamp);
- :func:`cancel_goal_request`: ``<action>/_action/cancel_goal`` for one goal id
  (``SKILL.interrupt``); :func:`cancel_goal_reply` reads the return code and the goals
  now canceling;
- :func:`get_result_request` / :func:`get_result_reply`: a terminal goal's status and
  result (the bridge names a mode from it);
- :func:`get_state_request` / :func:`get_state_reply`: a lifecycle node's state;
- :func:`lifecycle_transition`, :func:`change_state_request` / :func:`change_state_reply`:
  the transition that takes a lifecycle node from one primary state to another, and the
  ``change_state`` call that asks for it (a commanded event, docs/robot.md).

:class:`SentGoal` follows one goal a client sent, whichever comes first of the
server's reply and its status array (each crosses a gateway on its own route).
:func:`followed_goal` is the goal of a status array that runs the skill, as the
bridge's derivation follows it (:mod:`skinet.ros.bound`): the pilot cancels it when
it did not send the goal itself.

Pure: type stores from :func:`skinet.ros.definitions.build_store`; goal ids are
given by the caller (``uuid.uuid4().bytes``).  Cost: one CDR encoding or decoding.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from skinet.ros.binding import CANCEL_TYPE, CHANGE_STATE_TYPE, GET_STATE_TYPE
from skinet.ros.bound import ACTIVE, STATUS_NAMES, TERMINAL, Goal
from skinet.ros.stamp import ros_time
from skinet.ros.typestore import decode, default_instance, encode, to_plain

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

CANCEL_CODES = {0: "ERROR_NONE", 1: "ERROR_REJECTED", 2: "ERROR_UNKNOWN_GOAL_ID", 3: "ERROR_GOAL_TERMINATED"}


def goal_uuid(store: Typestore, goal_id: bytes) -> Any:
    """A ``unique_identifier_msgs/msg/UUID`` holding ``goal_id`` (16 bytes)."""
    if len(goal_id) != 16:
        raise ValueError(f"a goal id is a 16-byte UUID, got {len(goal_id)} bytes")
    return default_instance(store, "unique_identifier_msgs/msg/UUID",
                            uuid=np.frombuffer(goal_id, dtype=np.uint8).copy())


def message(store: Typestore, typename: str, values: Mapping[str, Any]) -> Any:
    """An instance of ``typename`` with ``values`` (nested dicts for nested messages), other fields default.

    Raises ``TypeError`` for a field the type lacks, with the fields it has.
    """
    from rosbags.typesys.base import normalize_fieldname

    _, fielddefs = store.fielddefs[typename]
    fields = dict(fielddefs)
    out: dict[str, Any] = {}
    for name, value in values.items():
        desc = fields.get(name)
        if desc is None:
            raise TypeError(f"{typename} has no field '{name}' (fields: {', '.join(fields)})")
        if isinstance(value, Mapping) and desc[0].name == "NAME":
            value = message(store, desc[1], value)
        out[normalize_fieldname(name)] = value
    return default_instance(store, typename, **out)


def send_goal_request(store: Typestore, action: str, goal_id: bytes, inputs: Mapping[str, Any] | None = None) -> bytes:
    """CDR of ``<action>_SendGoal_Request``: the goal id and the goal's fields from ``inputs``."""
    goal = message(store, f"{action}_Goal", inputs or {})
    return encode(store, f"{action}_SendGoal_Request", default_instance(
        store, f"{action}_SendGoal_Request", goal_id=goal_uuid(store, goal_id), goal=goal))


def send_goal_reply(store: Typestore, action: str, payload: bytes) -> tuple[bool, float]:
    """(accepted, stamp in seconds) of a ``<action>_SendGoal_Response``."""
    msg = decode(store, f"{action}_SendGoal_Response", payload)
    return bool(msg.accepted), msg.stamp.sec + msg.stamp.nanosec * 1e-9


def cancel_goal_request(store: Typestore, goal_id: bytes, stamp: float = 0.0) -> bytes:
    """CDR of ``action_msgs/srv/CancelGoal_Request`` for one goal (``stamp`` 0: that goal only).

    (A zero goal id with a stamp cancels every goal accepted before it, as ROS 2 defines it.)
    """
    sec, nanosec, _ = ros_time(stamp)  # clamped: every goal stamp past 2038 is clamped the same way
    info = default_instance(store, "action_msgs/msg/GoalInfo", goal_id=goal_uuid(store, goal_id),
                            stamp=default_instance(store, "builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec))
    return encode(store, f"{CANCEL_TYPE}_Request", default_instance(store, f"{CANCEL_TYPE}_Request", goal_info=info))


def cancel_goal_reply(store: Typestore, payload: bytes) -> tuple[str, list[bytes]]:
    """(return code name, ids of the goals now canceling) of a ``CancelGoal_Response``."""
    msg = decode(store, f"{CANCEL_TYPE}_Response", payload)
    return (CANCEL_CODES.get(int(msg.return_code), str(msg.return_code)),
            [bytes(g.goal_id.uuid) for g in msg.goals_canceling])


def get_result_request(store: Typestore, action: str, goal_id: bytes) -> bytes:
    """CDR of ``<action>_GetResult_Request`` for one goal."""
    return encode(store, f"{action}_GetResult_Request", default_instance(
        store, f"{action}_GetResult_Request", goal_id=goal_uuid(store, goal_id)))


def get_result_reply(store: Typestore, action: str, payload: bytes) -> tuple[int, dict[str, Any]]:
    """(goal status code, result fields as plain values) of a ``<action>_GetResult_Response``."""
    msg = decode(store, f"{action}_GetResult_Response", payload)
    return int(msg.status), to_plain(msg.result)


def get_state_request(store: Typestore) -> bytes:
    """CDR of ``lifecycle_msgs/srv/GetState_Request`` (it has no field)."""
    return encode(store, f"{GET_STATE_TYPE}_Request", default_instance(store, f"{GET_STATE_TYPE}_Request"))


def get_state_reply(store: Typestore, payload: bytes) -> tuple[int, str]:
    """(state id, label) of a ``GetState_Response``."""
    msg = decode(store, f"{GET_STATE_TYPE}_Response", payload)
    return int(msg.current_state.id), str(msg.current_state.label)


LIFECYCLE_TRANSITIONS: dict[tuple[int, int], tuple[int, str]] = {
    (1, 2): (1, "configure"), (2, 1): (2, "cleanup"), (2, 3): (3, "activate"), (3, 2): (4, "deactivate"),
    (1, 4): (5, "unconfigured_shutdown"), (2, 4): (6, "inactive_shutdown"), (3, 4): (7, "active_shutdown"),
}
"""(start, target primary state id) -> the lifecycle_msgs/msg/Transition id and label that leads there."""


def lifecycle_transition(start: int, target: int) -> tuple[int, str] | None:
    """The transition (id, label) from the primary state ``start`` to ``target``; None when none leads there.

    Examples:
        >>> lifecycle_transition(2, 3)
        (3, 'activate')
        >>> lifecycle_transition(1, 3) is None
        True
    """
    return LIFECYCLE_TRANSITIONS.get((start, target))


def change_state_request(store: Typestore, transition: int, label: str = "") -> bytes:
    """CDR of ``lifecycle_msgs/srv/ChangeState_Request`` for one transition id."""
    typename = f"{CHANGE_STATE_TYPE}_Request"
    return encode(store, typename, default_instance(store, typename, transition=default_instance(
        store, "lifecycle_msgs/msg/Transition", id=transition, label=label)))


def change_state_reply(store: Typestore, payload: bytes) -> bool:
    """Whether a ``ChangeState_Response`` says the transition succeeded."""
    return bool(decode(store, f"{CHANGE_STATE_TYPE}_Response", payload).success)


def followed_goal(goals: Sequence[Goal]) -> Goal | None:
    """The active goal (ACCEPTED, EXECUTING, CANCELING) with the earliest stamp: the one the bridge takes
    for the skill's run (a later concurrent goal is a drift, docs/semantics.md §9); ``None`` when none is active.

    Examples:
        >>> followed_goal([Goal(b"a" * 16, 2.0, 2), Goal(b"b" * 16, 1.0, 4), Goal(b"c" * 16, 3.0, 1)]).id[:1]
        b'a'
        >>> followed_goal([Goal(b"b" * 16, 1.0, 5)]) is None
        True
    """
    active = [g for g in goals if g.status in ACTIVE]
    return min(active, key=lambda g: (g.stamp, g.id)) if active else None


@dataclass
class SentGoal:
    """One goal a client sent: accepted by the reply *or* by a status array showing it, whichever
    comes first; ended by a terminal status."""

    id: bytes
    accepted: bool | None = None  # None until known
    status: int = 0  # last status seen (0: none)

    def on_reply(self, accepted: bool) -> None:
        if self.accepted is None or self.status == 0:
            self.accepted = accepted or self.status != 0

    def on_status(self, goals: Sequence[Goal]) -> bool:
        """Take a status array into account; True when it showed this goal."""
        for g in goals:
            if g.id == self.id:
                self.status = g.status
                if g.status in ACTIVE or g.status in TERMINAL:
                    self.accepted = True
                return True
        return False

    @property
    def done(self) -> bool:
        return self.status in TERMINAL or self.accepted is False

    def __str__(self) -> str:
        state = "waiting" if self.accepted is None else "rejected" if not self.accepted else \
            STATUS_NAMES.get(self.status, "accepted") if self.status else "accepted"
        return f"goal {self.id.hex()}: {state}"


__all__ = [
    "CANCEL_CODES", "SentGoal", "cancel_goal_reply", "cancel_goal_request", "followed_goal", "get_result_reply",
    "LIFECYCLE_TRANSITIONS", "change_state_reply", "change_state_request", "get_result_request",
    "get_state_reply", "lifecycle_transition", "get_state_request", "goal_uuid", "message", "send_goal_reply", "send_goal_request",
]
