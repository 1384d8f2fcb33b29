"""What an operator GUI puts on a skillset manager's request topics, in CDR (corpus README; docs/semantics.md §8).

A generated manager takes, on topics relative to its node (:func:`skinet.ros.keys.manager_topics`):

- ``skill/<k>/request``: ``Skill<K>Request`` (``id``, ``input``: a ``Skill<K>Input`` with
  the skill's input fields), which starts ``k`` (:func:`skill_request`); an accepted start
  gets no response, only the status showing the new id, and a refused one a
  ``Skill<K>Response`` first (:func:`start_refusal`);
- ``skill/<k>/interrupt``: ``SkillInterrupt`` (``id``), which interrupts ``k`` only when
  ``id`` is the running execution's id (:func:`skill_interrupt`); that id is read from
  the manager's own ``SkillsetStatus`` (:func:`skill_ids`), never guessed;
- ``event_request``: ``EventRequest`` (``id``, ``name``) (:func:`event_request`);
- ``status_request``: ``std_msgs/Empty``, after which the manager publishes its status.

The simulator's driver and the pilot send the same bytes on the same keys
(:class:`skinet.ros.keys.KeyStyle`); :class:`Writer` numbers the ``rmw_zenoh``
attachments of one writer.  Pure: the type store comes from
:func:`skinet.ros.typestore.build_typestore`.  Cost: one CDR encoding or decoding.

Examples:
    >>> from skinet.system.load import load_system, load_typemap
    >>> from skinet.ros.typestore import build_typestore
    >>> system, _ = load_system("skillsets/spot_arm.toml")
    >>> spot = system.component("spot").skillset
    >>> store = build_typestore(spot, load_typemap("skillsets/spot_arm.toml"))
    >>> topic, payload = skill_request(store, spot, "go_to_waypoint", "p1-1", {"target": {"x": 1.0}})
    >>> topic.topic, payload[:4]
    ('spot_skillset/skill/go_to_waypoint/request', b'\\x00\\x01\\x00\\x00')
    >>> skill_request(store, spot, "go_to_waypoint", "p1-2", {"goal": 1.0})
    Traceback (most recent call last):
    ...
    ValueError: spot:go_to_waypoint has no input 'goal' (inputs: target)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from skinet.lang.model import Skillset
from skinet.ros.actions import message
from skinet.ros.derive import SkillView, skill_response_from_plain, status_from_plain
from skinet.ros.interfaces import RESULTS, skill_type
from skinet.ros.keys import EMPTY_TYPE, GID_SIZE, ManagerTopic, TopicKind, manager_topics, rmw_attachment
from skinet.ros.typestore import decode, default_instance, encode, msg_typename, to_plain

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


def topic_of(skillset: Skillset, kind: TopicKind, skill: str | None = None) -> ManagerTopic:
    """The manager's topic of ``kind`` (for ``skill``, on skill topics); ``KeyError`` when it has none."""
    for t in manager_topics(skillset):
        if t.kind == kind and t.skill == skill:
            return t
    raise KeyError(f"{skillset.name} has no {kind} topic" + (f" for skill '{skill}'" if skill else ""))


def skill_request(store: Typestore, skillset: Skillset, skill: str, id_: str,
                  inputs: Mapping[str, Any] | None = None) -> tuple[ManagerTopic, bytes]:
    """``Skill<K>Request`` with ``id_`` and ``inputs`` (nested tables for messages; fields left out keep
    their defaults); ``ValueError`` for an input the skill lacks."""
    k = skillset.skill(skill)
    input_type = msg_typename(skillset, skill_type(k, "Input"))
    try:
        input_ = message(store, input_type, inputs or {})
    except TypeError:
        names = ", ".join(v.name for v in k.inputs) or "none"
        bad = next(iter(set(inputs or {}) - {v.name for v in k.inputs}), "?")
        raise ValueError(f"{skillset.name}:{skill} has no input '{bad}' (inputs: {names})") from None
    topic = topic_of(skillset, "skill_request", skill)
    return topic, encode(store, topic.typename, default_instance(store, topic.typename, id=id_, input=input_))


def request_inputs(store: Typestore, skillset: Skillset, skill: str, payload: bytes) -> tuple[str, dict[str, Any]]:
    """``(id, inputs)`` of a CDR ``Skill<K>Request`` (every input field, as plain values); ``ValueError`` when
    the payload is not one."""
    from rosbags.serde import SerdeError

    topic = topic_of(skillset, "skill_request", skill)
    try:
        msg = decode(store, topic.typename, payload)
        return str(msg.id), to_plain(msg.input)
    except (SerdeError, AttributeError) as exc:
        raise ValueError(f"not a request of {skillset.name}:{skill}: {exc}") from None


def plain_inputs(store: Typestore, skillset: Skillset, skill: str, inputs: Mapping[str, Any] | None) -> dict[str, Any]:
    """``inputs`` as :func:`request_inputs` reads them back from a request (fields left out at their
    defaults), to compare a start's inputs with a goal's."""
    k = skillset.skill(skill)
    return to_plain(message(store, msg_typename(skillset, skill_type(k, "Input")), inputs or {}))


def skill_interrupt(store: Typestore, skillset: Skillset, skill: str, id_: str) -> tuple[ManagerTopic, bytes]:
    """``SkillInterrupt`` with the running execution's ``id_`` (the manager ignores any other)."""
    topic = topic_of(skillset, "skill_interrupt", skill)
    return topic, encode(store, topic.typename, default_instance(store, topic.typename, id=id_))


def event_request(store: Typestore, skillset: Skillset, id_: str, name: str) -> tuple[ManagerTopic, bytes]:
    """``EventRequest`` for the event ``name``."""
    topic = topic_of(skillset, "event_request")
    return topic, encode(store, topic.typename, default_instance(store, topic.typename, id=id_, name=name))


def status_request(store: Typestore, skillset: Skillset) -> tuple[ManagerTopic, bytes]:
    """``std_msgs/Empty`` on ``status_request``: the manager answers with its status."""
    topic = topic_of(skillset, "status_request")
    return topic, encode(store, EMPTY_TYPE, default_instance(store, EMPTY_TYPE))


def skill_ids(store: Typestore, skillset: Skillset, payload: bytes) -> dict[str, SkillView]:
    """Each skill's state and current (or last) execution id in a CDR ``SkillsetStatus``; ``ValueError``
    when the payload is not one."""
    from rosbags.serde import SerdeError

    try:
        msg = to_plain(decode(store, msg_typename(skillset, "SkillsetStatus"), payload))
        return dict(status_from_plain(skillset, msg).skills)
    except KeyError as exc:
        raise ValueError(f"not a SkillsetStatus of {skillset.name}: no field {exc}") from None
    except SerdeError as exc:
        raise ValueError(f"not a SkillsetStatus of {skillset.name}: {exc}") from None


REFUSALS = ("ALREADY_RUNNING", "PRECONDITION_FAILURE", "VALIDATE_FAILURE", "START_FAILURE")


def start_refusal(store: Typestore, skillset: Skillset, skill: str, payload: bytes) -> tuple[str, str] | None:
    """``(id, why)`` when a CDR ``Skill<K>Response`` refuses a start (``ALREADY_RUNNING`` with the running
    execution's id, ``PRECONDITION_FAILURE`` with the preconditions that are false, ``VALIDATE_FAILURE``,
    ``START_FAILURE``); None for any other response; ``ValueError`` when the payload is not one."""
    from rosbags.serde import SerdeError

    k = skillset.skill(skill)
    try:
        msg = to_plain(decode(store, msg_typename(skillset, skill_type(k, "Response")), payload))
        r = skill_response_from_plain(skillset, skill, msg)
    except (KeyError, SerdeError) as exc:
        raise ValueError(f"not a response of {skillset.name}:{skill}: {exc}") from None
    code = next((c for c in REFUSALS if RESULTS[c] == r.result), None)
    if code == "ALREADY_RUNNING":
        return r.id, f"{code} (running id '{r.id}')"
    if code == "PRECONDITION_FAILURE":
        false = [name for name, ok in r.preconditions.items() if not ok]
        return r.id, f"{code} ({', '.join(false)} false)" if false else code
    return None if code is None else (r.id, code)


@dataclass
class Writer:
    """One writer of ROS 2 messages on Zenoh: its ``rmw_zenoh`` GID and sequence numbers."""

    gid: bytes
    sequence: int = 0

    def __post_init__(self) -> None:
        if len(self.gid) != GID_SIZE:
            raise ValueError(f"a GID has {GID_SIZE} bytes, got {len(self.gid)}")

    def attachment(self, timestamp_ns: int) -> bytes:
        """The next ``rmw_zenoh`` attachment (sequence numbers from 1)."""
        self.sequence += 1
        return rmw_attachment(self.sequence, timestamp_ns, self.gid)


__all__ = ["REFUSALS", "Writer", "event_request", "plain_inputs", "request_inputs", "skill_ids", "skill_interrupt",
           "skill_request", "start_refusal", "status_request", "topic_of"]
