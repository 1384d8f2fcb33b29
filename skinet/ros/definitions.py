"""ROS 2 message, service and action types from their definitions (docs/semantics.md §9).

``rosbags`` ships the standard *messages* of each distribution (``action_msgs``,
``lifecycle_msgs``, ``sensor_msgs``, ``geometry_msgs``, ...) but no service and no
action.  :func:`build_store` starts from its Humble store and registers:

- the standard services the action and lifecycle protocols use, written here from
  their documented fields (:data:`STANDARD`): ``action_msgs/srv/CancelGoal``,
  ``lifecycle_msgs/srv/GetState``, ``lifecycle_msgs/srv/ChangeState``;
- every definition a binding brings (``.msg``, ``.srv``, ``.action`` texts by type
  name, read from its ``definitions`` folder by :mod:`skinet.system.load`), with the
  default values of its fields (:mod:`skinet.ros.defaults`).

A service ``pkg/srv/Name`` (request ``---`` response) becomes ``Name_Request`` and
``Name_Response``; an action ``pkg/action/Name`` (goal ``---`` result ``---``
feedback) becomes ``Name_Goal``, ``Name_Result``, ``Name_Feedback`` and the types of
its protocol, as ``rosidl`` generates them::

    Name_SendGoal_Request   {unique_identifier_msgs/UUID goal_id, Name_Goal goal}
    Name_SendGoal_Response  {bool accepted, builtin_interfaces/Time stamp}
    Name_GetResult_Request  {unique_identifier_msgs/UUID goal_id}
    Name_GetResult_Response {int8 status, Name_Result result}
    Name_FeedbackMessage    {unique_identifier_msgs/UUID goal_id, Name_Feedback feedback}

Each service type (``Name_SendGoal`` and ``Name_GetResult`` too) also gets the
structure REP 2011 hashes for ``rmw_zenoh`` keys: ``request_message``,
``response_message`` and ``event_message`` (``Name_Event``: ``service_msgs``'
``ServiceEventInfo`` and at most one request and one response).  ``ServiceEventInfo``
is registered with ``uint8[16] client_gid``: ROS maps a ``.msg`` ``char`` to
``uint8``, and rosbags' Jazzy store, which keeps ``char``, hashes every service
differently from ROS (checked against published hashes in
``tests/ros/test_definitions.py``).

Pure; cost linear in the definitions' size, plus the import of ``rosbags`` (0.3-0.5 s) at
the first store or definition read, not at this module's import (docs/performance.md).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from skinet.errors import Pos, SourceError
from skinet.ros.defaults import DefaultError, definition_defaults, register

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

KINDS = ("msg", "srv", "action")
UUID = "unique_identifier_msgs/msg/UUID"
TIME = "builtin_interfaces/msg/Time"
EVENT_INFO = "service_msgs/msg/ServiceEventInfo"
EMPTY_FIELD = "structure_needs_at_least_one_member"
TYPENAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*/(msg|srv|action)/[A-Z][A-Za-z0-9_]*")

# Standard services that rosbags lacks, from their documented fields (ROS 2 Humble to Jazzy).
STANDARD: dict[str, str] = {
    "action_msgs/srv/CancelGoal": (
        "action_msgs/GoalInfo goal_info\n"
        "---\n"
        "int8 ERROR_NONE=0\n"
        "int8 ERROR_REJECTED=1\n"
        "int8 ERROR_UNKNOWN_GOAL_ID=2\n"
        "int8 ERROR_GOAL_TERMINATED=3\n"
        "int8 return_code\n"
        "action_msgs/GoalInfo[] goals_canceling\n"
    ),
    "lifecycle_msgs/srv/GetState": "---\nlifecycle_msgs/State current_state\n",
    "lifecycle_msgs/srv/ChangeState": "lifecycle_msgs/Transition transition\n---\nbool success\n",
}
_EVENT_INFO_TEXT = "uint8 event_type\nbuiltin_interfaces/Time stamp\nuint8[16] client_gid\nint64 sequence_number\n"

Typesdict = dict[str, tuple[list[Any], list[Any]]]


def sections(text: str) -> list[str]:
    """The parts of a ``.srv`` or ``.action`` text, split at lines holding only ``---``."""
    parts: list[list[str]] = [[]]
    for line in text.splitlines():
        if line.strip() == "---":
            parts.append([])
        else:
            parts[-1].append(line)
    return ["\n".join(p) + "\n" for p in parts]


def _message(text: str, name: str) -> Typesdict:
    """One message type named exactly ``name`` (rosbags would move ``pkg/srv/X`` to ``pkg/srv/msg/X``)."""
    from rosbags.interfaces import Nodetype
    from rosbags.typesys import get_types_from_msg

    (consts, fields), = get_types_from_msg(text, name).values()
    return {name: (consts, fields or [(EMPTY_FIELD, (Nodetype.BASE, ("uint8", 0)))])}


def _service(name: str, request: str, response: str) -> Typesdict:
    """``name_Request``, ``name_Response`` and the REP 2011 structure of the service ``name``."""
    from rosbags.interfaces import Nodetype

    types = _message(request, f"{name}_Request") | _message(response, f"{name}_Response")
    types[f"{name}_Event"] = ([], [
        ("info", (Nodetype.NAME, EVENT_INFO)),
        ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, f"{name}_Request"), 1))),
        ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, f"{name}_Response"), 1))),
    ])
    types[name] = ([], [
        ("request_message", (Nodetype.NAME, f"{name}_Request")),
        ("response_message", (Nodetype.NAME, f"{name}_Response")),
        ("event_message", (Nodetype.NAME, f"{name}_Event")),
    ])
    return types


def _action(name: str, goal: str, result: str, feedback: str) -> Typesdict:
    """The goal, result, feedback and protocol types of the action ``name`` (module docstring)."""
    types = _message(goal, f"{name}_Goal") | _message(result, f"{name}_Result") | _message(feedback, f"{name}_Feedback")
    types |= _service(f"{name}_SendGoal", f"unique_identifier_msgs/UUID goal_id\n{name}_Goal goal\n",
                      "bool accepted\nbuiltin_interfaces/Time stamp\n")
    types |= _service(f"{name}_GetResult", "unique_identifier_msgs/UUID goal_id\n",
                      f"int8 status\n{name}_Result result\n")
    types |= _message(f"unique_identifier_msgs/UUID goal_id\n{name}_Feedback feedback\n", f"{name}_FeedbackMessage")
    return types


def definition_types(typename: str, text: str, source: str = "<definitions>") -> Typesdict:
    """The types one definition gives (its kind is the middle part of ``typename``).

    Raises :class:`SourceError` at ``source`` for a malformed name or text.
    """
    if not TYPENAME.fullmatch(typename):
        raise SourceError.at(source, None, f"'{typename}' is not a ROS 2 type name (package/msg|srv|action/Name)")
    kind = typename.split("/")[1]
    parts = sections(text)
    expected = {"msg": 1, "srv": 2, "action": 3}[kind]
    if len(parts) != expected:
        raise SourceError.at(source, None, f"a .{kind} definition has {expected} part(s) separated by '---' lines, "
                                           f"this one has {len(parts)}")
    try:
        if kind == "msg":
            return _message(text, typename)
        if kind == "srv":
            return _service(typename, *parts)
        return _action(typename, *parts)
    except Exception as exc:  # rosbags' parser raises its own errors (and others) on bad text
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SourceError.at(source, None, f"cannot read the definition of {typename}: {first}") from None


def build_store(definitions: Mapping[str, str] | None = None,
                sources: Mapping[str, str] | None = None) -> Typestore:
    """Humble's message store, the standard services above and ``definitions`` (type name -> text).

    ``sources`` names the file of each definition for errors.  A definition that
    contradicts a type already known is an error at its file.
    """
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types: Typesdict = _message(_EVENT_INFO_TEXT, EVENT_INFO)
    for name, text in STANDARD.items():
        types |= definition_types(name, text)
    store.register(types)
    for name, text in (definitions or {}).items():
        source = (sources or {}).get(name, "<definitions>")
        new = definition_types(name, text, source)
        try:
            store.register(new)
        except Exception as exc:  # rosbags: "already present with different definition", unknown field types
            raise SourceError.at(source, None, f"cannot register {name}: {exc}") from None
        try:
            register(store, definition_defaults(name, sections(text)))
        except DefaultError as exc:
            raise SourceError.at(source, Pos(exc.line, exc.column), f"cannot read the definition of {name}: {exc}") \
                from None
    return store


def action_types(store: Typestore) -> list[str]:
    """The actions ``store`` knows (``pkg/action/Name``), sorted."""
    return sorted(n[: -len("_SendGoal")] for n in store.fielddefs if n.endswith("_SendGoal") and "/action/" in n)


def known(store: Typestore, typename: str) -> bool:
    """Whether ``store`` can encode and decode ``typename``."""
    return typename in store.fielddefs


def rihs01(store: Typestore, typename: str) -> str:
    """``RIHS01_<sha256>`` of a message or service type (a service: its REP 2011 structure)."""
    return store.hash_rihs01(typename)


__all__ = ["KINDS", "STANDARD", "action_types", "build_store", "definition_types", "known", "rihs01", "sections"]
