"""Binding files: a skillset's skills, resources and events on plain ROS 2 interfaces (docs/semantics.md §9).

A binding (TOML, named by ``binding = "..."`` in a system file's ``[[skillsets]]``
entry) lets the bridge play the part of a skillset manager::

    [binding]
    definitions = "interfaces"            # .msg/.srv/.action files: <pkg>/action/<Name>.action, ...

    [skills.navigate]                     # a skill <-> an action server
    action = "/navigate_to_pose"
    type = "nav2_msgs/action/NavigateToPose"
    success = "arrived"                   # mode of a SUCCEEDED goal
    failure = "failed"                    # mode of an ABORTED goal, unless a condition below holds
    failure_when = { timed_out = "error_code == TIMEOUT" }   # on the result, tried in order
    inputs = { target = "pose" }          # the skill's input target is the goal's field pose (acting)
    goal = { behavior_tree = "" }         # goal fields sent with every goal the pilot sends

    [resources.navigator]                 # a resource <-> a lifecycle node
    lifecycle = "/bt_navigator"
    states = { Inactive = "inactive", Active = "active" }    # model state = lifecycle state
    commanded = true                      # its changes are commands (someone activates it), not the robot's

    [resources.battery]                   # a resource <-> a topic, a condition per state
    topic = "/battery_state"
    type = "sensor_msgs/msg/BatteryState"
    states = { Low = "percentage < 0.2", Ok = "percentage >= 0.2" }

    [events.charger_unplugged]            # an event <-> the rising edge of a topic condition
    topic = "/battery_state"
    type = "sensor_msgs/msg/BatteryState"
    when = "power_supply_status == POWER_SUPPLY_STATUS_DISCHARGING"

:func:`parse_binding` checks every name against the skillset (unknown skill,
resource, state, event or mode: an error with close names), every type against
the type store of :mod:`skinet.ros.definitions` (rosbags' standard messages plus
the binding's definitions) and every condition (:mod:`skinet.ros.condition`), and
reports each error at the file, line and column of the key or value.  A skill
without a binding is a warning: the bridge never sees it run.

Acting (docs/semantics.md §9, *Acting*): the pilot's ``k.start`` sends a goal of ``k``'s action
(:meth:`SkillBinding.goal_fields`): the fixed fields of ``goal``, then each input
of the skill at its goal field (``inputs``: input -> field path, dotted for a
nested field such as ``pose.pose.position.x``; an input named like a top-level
goal field needs no entry).  Every input of the skill must reach a goal field,
every path must name one, and ``goal`` must type-check against the goal message.

A bound resource's change is an event of the skillset (the model's event that
explains it), uncontrollable unless the binding says the resource is
``commanded`` (docs/semantics.md §9): then every event of the model that changes it is
controllable (:attr:`Binding.commanded`, :func:`commanded_events`; docs/semantics.md §5, §6.3,
§8: it never counts as an uncontrollable step, whatever ``events_uncontrollable``
says).  An event bound to a topic condition is the robot's own, so it cannot change
a commanded resource.

Pure (the definitions come in as texts, read by :mod:`skinet.system.load`); cost linear
in the file.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from skinet.closenames import close_names, unknown
from skinet.errors import Diagnostic, Pos, SourceError
from skinet.lang.model import Skill, Skillset
from skinet.plan.inputs import message_problem
from skinet.ros.condition import Condition, example_message, parse_condition
from skinet.ros.definitions import action_types, build_store
from skinet.files.toml import locate_path, parse_toml

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

# lifecycle_msgs/msg/State ids of the primary states (transition states 10-15 settle into one of them).
LIFECYCLE_STATES: dict[str, int] = {"unconfigured": 1, "inactive": 2, "active": 3, "finalized": 4}
STATUS_TYPE = "action_msgs/msg/GoalStatusArray"
TRANSITION_EVENT_TYPE = "lifecycle_msgs/msg/TransitionEvent"
GET_STATE_TYPE = "lifecycle_msgs/srv/GetState"
CHANGE_STATE_TYPE = "lifecycle_msgs/srv/ChangeState"
CANCEL_TYPE = "action_msgs/srv/CancelGoal"
ROS_NAME = re.compile(r"/?[A-Za-z_~][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")

_KEYS: dict[str, tuple[str, ...]] = {
    "": ("binding", "events", "resources", "skills"),
    "binding": ("definitions", "skillset"),
    "skills": ("action", "failure", "failure_when", "goal", "inputs", "success", "success_when", "type"),
    "resources": ("commanded", "lifecycle", "states", "topic", "type"),
    "events": ("topic", "type", "when"),
}


@dataclass(frozen=True)
class Outcome:
    """How the goals of one terminal status (SUCCEEDED or ABORTED) name their mode."""

    default: str | None  # mode name ('' for an unnamed mode); None: the model has no mode of this kind
    when: tuple[tuple[str, Condition], ...] = ()  # (mode, condition on the action's result), tried in order

    def mode(self, result: Mapping[str, Any] | None) -> str | None:
        """The mode of a goal whose result is ``result`` (``None``: unknown, the default)."""
        if result is not None:
            for mode, condition in self.when:
                if condition.holds(result):
                    return mode
        return self.default


@dataclass(frozen=True)
class SkillBinding:
    skill: str
    action: str  # fully qualified ROS name: /navigate_to_pose
    type: str  # nav2_msgs/action/NavigateToPose
    success: Outcome
    failure: Outcome
    inputs: tuple[tuple[str, tuple[str, ...]], ...] = ()  # (skill input, goal field path), every input of the skill
    goal: Mapping[str, Any] = field(default_factory=dict, hash=False)  # fixed goal fields (nested tables for messages)

    def name(self, suffix: str) -> str:
        """A name of the action's protocol: ``status``, ``send_goal``, ``get_result``, ``cancel_goal``, ``feedback``."""
        return f"{self.action}/_action/{suffix}"

    def goal_fields(self, inputs: Mapping[str, Any]) -> dict[str, Any]:
        """The goal's fields (nested dicts) for a start with ``inputs``: the fixed ``goal`` fields, then
        each input given at its field.  ``KeyError`` names an input the skill does not have.

        Examples:
            >>> b = SkillBinding("dock_robot", "/dock_robot", "opennav_docking_msgs/action/DockRobot",
            ...                  Outcome("docked"), Outcome("failed"), (("dock", ("dock_id",)),),
            ...                  {"use_dock_id": True})
            >>> b.goal_fields({"dock": "home"})
            {'use_dock_id': True, 'dock_id': 'home'}
        """
        out = copy.deepcopy(dict(self.goal))
        paths = dict(self.inputs)
        for name, value in inputs.items():
            if name not in paths:
                raise KeyError(f"'{name}' is not an input of {self.skill}")
            *parents, last = paths[name]
            at = out
            for part in parents:
                at = at.setdefault(part, {})
            at[last] = value
        return out

    def goal_problem(self, inputs: Mapping[str, Any], store: Typestore) -> str | None:
        """Why a start with ``inputs`` could not be sent (its goal message, with the fixed fields), or None."""
        try:
            fields = self.goal_fields(inputs)
        except KeyError as exc:
            return str(exc.args[0])
        problem = message_problem(fields, f"{self.type}_Goal", store)
        return f"the goal of {self.action} cannot be sent: {problem}" if problem else None

    @property
    def needs_result(self) -> bool:
        """Whether a mode depends on the result (the bridge then asks ``get_result``)."""
        return bool(self.success.when or self.failure.when)


@dataclass(frozen=True)
class ResourceBinding:
    """A resource observed through a lifecycle node (``lifecycle``) or a topic (``topic``, ``type``)."""

    resource: str
    states: tuple[tuple[str, Any], ...]  # (model state, lifecycle state id) or (model state, Condition)
    lifecycle: str = ""  # the node: /bt_navigator
    topic: str = ""
    type: str = ""
    commanded: bool = False  # its changes are commands (controllable events), not the robot's own

    @property
    def transition_event(self) -> str:
        return f"{self.lifecycle}/transition_event"

    @property
    def get_state(self) -> str:
        return f"{self.lifecycle}/get_state"

    @property
    def change_state(self) -> str:
        return f"{self.lifecycle}/change_state"

    def lifecycle_state(self, state_id: int) -> str | None:
        """The model state of a primary lifecycle state id (``None``: not mapped)."""
        return next((s for s, i in self.states if i == state_id), None)


@dataclass(frozen=True)
class EventBinding:
    event: str
    topic: str
    type: str
    when: Condition


@dataclass(frozen=True)
class Binding:
    """The checked binding of one skillset."""

    skillset: str
    source: str
    skills: tuple[SkillBinding, ...] = ()
    resources: tuple[ResourceBinding, ...] = ()
    events: tuple[EventBinding, ...] = ()
    store: Typestore | None = field(default=None, compare=False, repr=False)
    definitions: str = ""  # the folder named by [binding] definitions, as written
    warnings: tuple[Diagnostic, ...] = ()
    commanded: frozenset[str] = frozenset()  # events of the model that change a commanded resource

    def topics(self) -> dict[str, str]:
        """Every topic the bridge reads (ROS name -> message type): action statuses, lifecycle
        transition events, bound topics."""
        out = {s.name("status"): STATUS_TYPE for s in self.skills}
        out |= {r.transition_event: TRANSITION_EVENT_TYPE for r in self.resources if r.lifecycle}
        out |= {r.topic: r.type for r in self.resources if r.topic}
        out |= {e.topic: e.type for e in self.events}
        return out

    def skill(self, name: str) -> SkillBinding | None:
        return next((s for s in self.skills if s.skill == name), None)


def bound_inputs_problem(bindings: Mapping[str, Binding], skillset: str, skill: str,
                         inputs: Mapping[str, Any]) -> str | None:
    """Why a start of ``skillset:skill`` with ``inputs`` could not be sent (``skillset:skill: why``), or None: it
    could, or the skill is bound to no action (nothing to check here)."""
    binding = bindings.get(skillset)
    bound = binding.skill(skill) if binding is not None else None
    if binding is None or bound is None or binding.store is None:
        return None
    problem = bound.goal_problem(inputs, binding.store)
    return f"{skillset}:{skill}: {problem}" if problem else None


def definitions_folder(text: str, source: str) -> str:
    """``[binding] definitions`` of a binding text ('' when absent), for the loader to read first."""
    data = parse_toml(text, source)
    head = data.get("binding", {})
    folder = head.get("definitions", "") if isinstance(head, dict) else ""
    if not isinstance(folder, str):
        raise SourceError.at(source, locate_path(text, ("binding", "definitions"), True),
                             "[binding] definitions must be a folder path string")
    return folder


class _Parser:
    def __init__(self, text: str, source: str, skillset: Skillset, store: Typestore):
        self.text = text
        self.source = source
        self.skillset = skillset
        self.store = store
        self.topic_types: dict[str, tuple[str, tuple[str, ...]]] = {}

    def error(self, path: tuple[str, ...], message: str, value: bool = False) -> SourceError:
        pos = locate_path(self.text, path, value)
        if pos is None and len(path) > 1:  # a key not written (missing): point at its table
            pos = locate_path(self.text, path[:-1])
        return SourceError.at(self.source, pos, message)

    def commanded(self, name: str, table: dict[str, Any]) -> frozenset[str]:
        """The events that change resource ``name`` when its table says ``commanded = true`` (else none)."""
        path = ("resources", name, "commanded")
        value = table.get("commanded", False)
        if not isinstance(value, bool):
            raise self.error(path, f"[resources.{name}] commanded must be true or false, not {value!r}", True)
        if not value:
            return frozenset()
        events = changing(self.skillset, name)
        if not events:
            raise self.error(path, f"[resources.{name}] commanded = true, but no event of skillset "
                                   f"'{self.skillset.name}' changes {name}: only events can be commanded", True)
        return events

    def table(self, value: object, path: tuple[str, ...], what: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(path, f"{what} must be a table", True)
        return value

    def keys(self, table: dict[str, Any], path: tuple[str, ...], kind: str) -> None:
        known = _KEYS[kind]
        for key in table:
            if key not in known:
                where = f"[{'.'.join(path)}]" if path else "the binding"
                raise self.error((*path, key), unknown("key", key, known, f" in {where}"))

    def string(self, table: dict[str, Any], path: tuple[str, ...], key: str, required: bool = True) -> str:
        if key not in table:
            if required:
                raise self.error(path, f"[{'.'.join(path)}] needs '{key}'")
            return ""
        value = table[key]
        if not isinstance(value, str) or not value:
            raise self.error((*path, key), f"[{'.'.join(path)}] {key} must be a non-empty string", True)
        return value

    def ros_name(self, table: dict[str, Any], path: tuple[str, ...], key: str) -> str:
        name = self.string(table, path, key)
        if not ROS_NAME.fullmatch(name):
            raise self.error((*path, key), f"'{name}' is not a ROS 2 name (e.g. /navigate_to_pose)", True)
        return name if name.startswith("/") else "/" + name

    def condition(self, text: object, typename: str, path: tuple[str, ...]) -> Condition:
        if not isinstance(text, str):
            raise self.error(path, f"the condition of {path[-1]} must be a string", True)
        at = locate_path(self.text, path, True) or Pos(1, 1)
        return parse_condition(text, typename, self.store, self.source, at)

    def message_type(self, table: dict[str, Any], path: tuple[str, ...], topic: str) -> str:
        typename = self.string(table, path, "type")
        if typename not in self.store.fielddefs or "/msg/" not in typename:
            candidates = [n for n in self.store.fielddefs if "/msg/" in n]
            close = close_names(typename, candidates)
            message = unknown("message type", typename, close) if close else (
                f"unknown message type '{typename}' (not among rosbags' standard messages nor the binding's "
                "definitions)")
            raise self.error((*path, "type"), message, True)
        previous = self.topic_types.get(topic)
        if previous is not None and previous[0] != typename:
            raise self.error((*path, "type"), f"topic {topic} is bound as {previous[0]} in "
                                              f"[{'.'.join(previous[1])}] and as {typename} here", True)
        self.topic_types[topic] = (typename, path)
        return typename

    # -- sections ---------------------------------------------------------------------------

    def section(self, kind: str, name: str, table: object, names: Sequence[str]) -> dict[str, Any]:
        """The table ``[<kind>s.<name>]``, checked: ``name`` one of the model's ``names``, known keys only."""
        path = (f"{kind}s", name)
        if name not in names:
            raise self.error(path, unknown(kind, name, names, f" of skillset '{self.skillset.name}'"))
        table = self.table(table, path, f"[{kind}s.{name}]")
        self.keys(table, path, f"{kind}s")
        return table

    def skill(self, name: str, table: object) -> SkillBinding:
        path = ("skills", name)
        skills = {k.name: k for k in self.skillset.skills}
        table = self.section("skill", name, table, list(skills))
        action = self.ros_name(table, path, "action")
        typename = self.string(table, path, "type")
        known = action_types(self.store)
        if typename not in known:
            raise self.error((*path, "type"), unknown("action type", typename, known) + "; put its .action file in "
                                              "the binding's definitions folder as <package>/action/<Name>.action",
                             True)
        skill = skills[name]
        goal = self.fixed_goal(table, path, typename)
        return SkillBinding(name, action, typename, self.outcome(table, path, skill, "success", typename),
                            self.outcome(table, path, skill, "failure", typename),
                            self.inputs(table, path, skill, typename, goal), goal)

    def fixed_goal(self, table: dict[str, Any], path: tuple[str, ...], action: str) -> dict[str, Any]:
        """``goal``: fixed goal fields, checked against ``<action>_Goal``."""
        if "goal" not in table:
            return {}
        goal = self.table(table["goal"], (*path, "goal"), f"[skills.{path[1]}] goal")
        fields = self.fields(f"{action}_Goal")
        for name, value in goal.items():
            if name not in fields:
                raise self.error((*path, "goal", name), unknown("field", name, list(fields), f" of {action}_Goal"))
            problem = message_problem({name: value}, f"{action}_Goal", self.store)
            if problem:
                raise self.error((*path, "goal", name), f"[skills.{path[1]}] goal: {problem}", True)
        return goal

    def fields(self, typename: str) -> dict[str, Any]:
        return dict(self.store.fielddefs[typename][1])

    def inputs(self, table: dict[str, Any], path: tuple[str, ...], skill: Skill, action: str,
               goal: Mapping[str, Any]) -> tuple[tuple[str, tuple[str, ...]], ...]:
        """Every input of ``skill`` with the goal field it fills (``inputs``, else the field of its name)."""
        goal_type = f"{action}_Goal"
        declared = [v.name for v in skill.inputs]
        given = self.table(table.get("inputs", {}), (*path, "inputs"), f"[skills.{skill.name}] inputs")
        out: dict[str, tuple[str, ...]] = {}
        for name, target in given.items():
            key = (*path, "inputs", name)
            if name not in declared:
                raise self.error(key, unknown("input", name, declared, f" of skill '{skill.name}'"))
            if not isinstance(target, str) or not target:
                raise self.error(key, f"[skills.{skill.name}] inputs: the goal field of input '{name}' must be a "
                                      "field name such as \"pose\" or \"pose.pose.position.x\"", True)
            out[name] = self.field_path(target, goal_type, key)
        for name in declared:
            if name not in out:
                if name not in self.fields(goal_type):
                    raise self.error(path, f"input '{name}' of skill '{skill.name}' reaches no field of {goal_type}: "
                                           f"map it with inputs = {{ {name} = \"<field>\" }} (fields: "
                                           f"{', '.join(self.fields(goal_type))})")
                out[name] = (name,)
        seen: dict[tuple[str, ...], str] = {}
        for name, field_path in out.items():
            for other, other_path in seen.items():
                shorter = min(len(field_path), len(other_path))
                if field_path[:shorter] == other_path[:shorter]:
                    raise self.error((*path, "inputs", name) if name in given else path,
                                     f"inputs '{other}' and '{name}' of skill '{skill.name}' both set goal field "
                                     f"{'.'.join(field_path[:shorter])}")
            seen[field_path] = name
            if field_path[0] in goal:
                raise self.error((*path, "goal", field_path[0]), f"goal field {field_path[0]} is fixed by "
                                 f"[skills.{skill.name}] goal and set by input '{name}': keep one")
        return tuple(out.items())

    def field_path(self, text: str, typename: str, key: tuple[str, ...]) -> tuple[str, ...]:
        """The field path ``pose.pose.position.x`` of ``typename``, checked part by part."""
        parts = tuple(text.split("."))
        current = typename
        for n, part in enumerate(parts):
            if current is None:
                raise self.error(key, f"{'.'.join(parts[:n])} is not a message: it has no field '{part}'", True)
            fields = self.fields(current)
            if part not in fields:
                raise self.error(key, unknown("field", part, list(fields), f" of {current}"), True)
            desc = fields[part]
            current = desc[1] if desc[0].name == "NAME" else None
        return parts

    def outcome(self, table: dict[str, Any], path: tuple[str, ...], skill: Skill, kind: str, action: str) -> Outcome:
        modes = [m.name for m in (skill.successes if kind == "success" else skill.failures)]
        shown = ", ".join(f"'{m}'" for m in modes) or "none"

        def check(mode: object, key: tuple[str, ...]) -> str:
            if not isinstance(mode, str) or mode not in modes:
                raise self.error(key, unknown(f"{kind} mode", str(mode), modes, f" of skill '{skill.name}'"),
                                 key[-1] == kind)
            return mode

        if kind in table:
            default: str | None = check(table[kind], (*path, kind))
        elif len(modes) == 1:
            default = modes[0]
        elif modes:
            raise self.error(path, f"skill '{skill.name}' has several {kind} modes ({shown}): name the mode of "
                                   f"{'a SUCCEEDED' if kind == 'success' else 'an ABORTED'} goal with {kind} = \"...\"")
        else:
            default = None
        when = []
        key = f"{kind}_when"
        if key in table:
            for mode, text in self.table(table[key], (*path, key), f"[skills.{skill.name}] {key}").items():
                when.append((check(mode, (*path, key, mode)), self.condition(text, f"{action}_Result",
                                                                             (*path, key, mode))))
        return Outcome(default, tuple(when))

    def resource(self, name: str, table: object) -> ResourceBinding:
        path = ("resources", name)
        resources = {r.name: r for r in self.skillset.resources}
        table = self.section("resource", name, table, list(resources))
        model = resources[name]
        commanded = bool(self.commanded(name, table))
        if ("lifecycle" in table) == ("topic" in table):
            raise self.error(path, f"[resources.{name}] needs either 'lifecycle' (a lifecycle node) or 'topic'")
        states = table.get("states")
        if states is not None:
            states = self.table(states, (*path, "states"), f"[resources.{name}] states")
            for state in states:
                if state not in model.states:
                    raise self.error((*path, "states", state),
                                     unknown("state", state, model.states, f" of resource '{name}'"))
        if "lifecycle" in table:
            if "type" in table:
                raise self.error((*path, "type"), f"[resources.{name}] a lifecycle node has no 'type' "
                                                  f"(its transition events are {TRANSITION_EVENT_TYPE})")
            node = self.ros_name(table, path, "lifecycle")
            if states is None:  # model states named like the lifecycle's (Active = active)
                states = {s: s.lower() for s in model.states if s.lower() in LIFECYCLE_STATES}
                if not states:
                    raise self.error(path, f"[resources.{name}] needs 'states': model state = lifecycle state "
                                           f"({', '.join(LIFECYCLE_STATES)})")
            pairs, seen = [], set()
            for state, label in states.items():
                if label not in LIFECYCLE_STATES:
                    raise self.error((*path, "states", state),
                                     unknown("lifecycle state", str(label), list(LIFECYCLE_STATES)), True)
                if label in seen:
                    raise self.error((*path, "states", state), f"lifecycle state '{label}' is bound twice", True)
                seen.add(label)
                pairs.append((state, LIFECYCLE_STATES[label]))
            return ResourceBinding(name, tuple(pairs), lifecycle=node, commanded=commanded)
        topic = self.ros_name(table, path, "topic")
        typename = self.message_type(table, path, topic)
        if not states:
            raise self.error(path, f"[resources.{name}] needs 'states': a condition on {typename} per state, "
                                   "e.g. states = { Low = \"percentage < 0.2\" }")
        pairs = [(state, self.condition(text, typename, (*path, "states", state))) for state, text in states.items()]
        return ResourceBinding(name, tuple(pairs), topic=topic, type=typename, commanded=commanded)

    def event(self, name: str, table: object) -> EventBinding:
        path = ("events", name)
        table = self.section("event", name, table, [e.name for e in self.skillset.events])
        topic = self.ros_name(table, path, "topic")
        typename = self.message_type(table, path, topic)
        if "when" not in table:
            raise self.error(path, f"[events.{name}] needs 'when': the condition whose rising edge fires it")
        return EventBinding(name, topic, typename, self.condition(table["when"], typename, (*path, "when")))


def parse_binding(text: str, source: str, skillset: Skillset, definitions: Mapping[str, str] | None = None,
                  definition_sources: Mapping[str, str] | None = None) -> Binding:
    """Check a binding text against ``skillset``; raises :class:`SourceError` (one line) on any defect.

    ``definitions`` maps type names (``nav2_msgs/action/NavigateToPose``) to their
    ``.msg``/``.srv``/``.action`` texts, ``definition_sources`` to their files.
    """
    data = parse_toml(text, source)
    store = build_store(definitions, definition_sources)
    p = _Parser(text, source, skillset, store)
    p.keys(data, (), "")
    head = p.table(data.get("binding", {}), ("binding",), "[binding]")
    p.keys(head, ("binding",), "binding")
    named = head.get("skillset")
    if named is not None and named != skillset.name:
        raise p.error(("binding", "skillset"), f"this binding is for skillset {named!r}, the system file gives it "
                                               f"to '{skillset.name}'", True)
    sections: dict[str, dict[str, Any]] = {}
    for section in ("skills", "resources", "events"):
        sections[section] = p.table(data.get(section, {}), (section,), f"[{section}]")
    skills = tuple(p.skill(n, t) for n, t in sections["skills"].items())
    resources = tuple(p.resource(n, t) for n, t in sections["resources"].items())
    events = tuple(p.event(n, t) for n, t in sections["events"].items())
    if not (skills or resources or events):
        raise SourceError.at(source, None, "the binding binds nothing: add [skills.<skill>], [resources.<resource>] "
                                           "or [events.<event>] tables")
    commanded = frozenset(e for r in resources if r.commanded for e in changing(skillset, r.resource))
    for e in events:
        if e.event in commanded:
            moved = next(r.resource for r in resources if r.commanded and e.event in changing(skillset, r.resource))
            raise p.error(("events", e.event), f"[events.{e.event}] binds event '{e.event}' to a topic condition (the "
                                               f"robot's own), but it changes {moved}, which [resources.{moved}] "
                                               "says is commanded")
    bound = {s.skill for s in skills}
    warnings = tuple(Diagnostic(source, None, "warning", f"skill '{k.name}' has no binding: the bridge never sees "
                                                         "it run")
                     for k in skillset.skills if k.name not in bound)
    return Binding(skillset.name, source, skills, resources, events, store, definition_folder_of(head), warnings,
                   commanded)


def changing(skillset: Skillset, resource: str) -> frozenset[str]:
    """The events of ``skillset`` whose effects change ``resource``."""
    return frozenset(e.name for e in skillset.events if any(f.resource == resource for f in e.effects))


def commanded_events(text: str, source: str, skillset: Skillset) -> frozenset[str]:
    """The events of ``skillset`` that a binding text makes controllable (its ``commanded`` resources), for the
    system's nets (:func:`skinet.system.load.load_system`), without the binding's message types: only the
    ``commanded`` keys are checked here (errors at their position); :func:`parse_binding` checks the rest."""
    data = parse_toml(text, source)
    p = _Parser(text, source, skillset, None)  # type: ignore[arg-type]
    tables = data.get("resources")
    names = {r.name for r in skillset.resources}
    out: frozenset[str] = frozenset()
    for name, table in (tables.items() if isinstance(tables, dict) else ()):
        if name in names and isinstance(table, dict):
            out |= p.commanded(name, table)
    return out


def lifecycle_events(text: str, source: str, skillset: Skillset) -> frozenset[str]:
    """The events of ``skillset`` that change a resource a binding text binds to a lifecycle node: those a
    lifecycle manager could command (a plan's ``none`` names them when it needs them, docs/planning.md).
    Malformed tables are skipped: :func:`parse_binding` reports them."""
    data = parse_toml(text, source)
    tables = data.get("resources")
    names = {r.name for r in skillset.resources}
    out: frozenset[str] = frozenset()
    for name, table in (tables.items() if isinstance(tables, dict) else ()):
        if name in names and isinstance(table, dict) and table.get("lifecycle"):
            out |= changing(skillset, name)
    return out


def definition_folder_of(head: Mapping[str, Any]) -> str:
    folder = head.get("definitions", "")
    return folder if isinstance(folder, str) else ""


# -- a simulated robot's side of a binding (services/simulator) ----------------------------------------------


def result_fields(skill: SkillBinding, kind: str, mode: str, store: Typestore) -> dict[str, Any] | None:
    """The fields of a result that names ``mode`` of ``kind`` (``success``: a SUCCEEDED goal, ``failure``:
    ABORTED; ``''``: the binding's default mode): the first ``<kind>_when`` condition of ``mode`` true and
    every earlier one false, or (the default) none of them true.  None when no such result is found
    (:func:`~skinet.ros.condition.example_message`) or ``mode`` is not one the binding names."""
    outcome = skill.success if kind == "success" else skill.failure
    mode = mode or outcome.default or ""
    earlier = [(c, False) for _, c in outcome.when]
    for i, (named, condition) in enumerate(outcome.when):
        if named == mode:
            return example_message([*earlier[:i], (condition, True)], store)
    return example_message(earlier, store) if mode == outcome.default else None


def first_samples(binding: Binding, skillset: Skillset) -> dict[str, dict[str, Any]]:
    """A first message of each topic ``binding`` reads (ROS name -> fields) that shows every resource bound
    to it in its initial state and fires none of its events: what a simulated robot publishes before anything
    happens.  Raises ``ValueError`` naming a topic for which no such message is found."""
    out: dict[str, dict[str, Any]] = {}
    for topic in dict.fromkeys([r.topic for r in binding.resources if r.topic] + [e.topic for e in binding.events]):
        shown: list[tuple[Condition, bool]] = []
        others: list[tuple[Condition, bool]] = []  # the other states false, when the conditions allow it
        for r in binding.resources:
            if r.topic == topic:
                initial = skillset.resource(r.resource).initial
                shown += [(c, True) for state, c in r.states if state == initial]
                others += [(c, False) for state, c in r.states if state != initial]
        quiet = [(e.when, False) for e in binding.events if e.topic == topic]
        found = example_message([*shown, *others, *quiet], binding.store) if binding.store is not None else None
        if found is None and binding.store is not None:
            found = example_message([*shown, *quiet], binding.store)
        if found is None:
            what = ", ".join(f"{r.resource} {skillset.resource(r.resource).initial}" for r in binding.resources
                             if r.topic == topic)
            raise ValueError(f"{binding.source}: no {topic} message found that shows {what or 'no event'}"
                             f"{' and fires no event' if quiet and what else ''}")
        out[topic] = found
    return out


__all__ = [
    "Binding", "CANCEL_TYPE", "EventBinding", "GET_STATE_TYPE", "LIFECYCLE_STATES", "Outcome", "ResourceBinding",
    "STATUS_TYPE", "CHANGE_STATE_TYPE", "SkillBinding", "TRANSITION_EVENT_TYPE", "changing", "commanded_events", "definitions_folder",
    "first_samples", "lifecycle_events", "parse_binding", "result_fields",
]
