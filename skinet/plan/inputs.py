"""Skill inputs of a goal (docs/semantics.md §8, *Skill inputs*): which skill gets which values, checked.

A start needs values for the skill's ``input`` fields; a goal gives them per
skill, and a plan starts a skill only when the goal gives all of its inputs.
``inputs`` is a table of skills (``go_to_waypoint`` when no other skillset of
the system has a skill of that name, else ``"spot:go_to_waypoint"``), each a
table of input values::

    inputs = { go_to_waypoint = { target = { x = 12.0, y = 3.5, z = 0.0 } } }

A value is checked against its input's type where the type is known: a ROS
primitive type name (``float64``, ``string``, ...), or a type that the
system's type map (``[system] types``) maps to a ROS primitive or message;
a message takes a table of its fields (fields left out keep their defaults)
and each field is checked in turn.  A type the map does not name accepts any
value (the model alone does not say what it is).  Cost: linear in the size of
the values, plus rosbags' type store the first time a message is checked.

Examples:
    >>> from skinet.system.load import load_system
    >>> system, _ = load_system("skillsets/spot_arm.toml")
    >>> parse_inputs(system, {"go_to_waypoint": {"target": {"x": 1.0}}}, "<inputs>")
    {('spot', 'go_to_waypoint'): {'target': {'x': 1.0}}}
    >>> parse_inputs(system, {"go_to_waypoint": {"goal": 1.0}}, "<inputs>")
    Traceback (most recent call last):
    ...
    skinet.errors.SourceError: <inputs>: error: unknown input 'goal' of spot:go_to_waypoint (expected one of: target)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import cache
from typing import Any

from skinet.closenames import unknown
from skinet.errors import Pos, SourceError
from skinet.lang.model import Skill, Variable
from skinet.system.model import System

Inputs = dict[tuple[str, str], dict[str, Any]]
"""(skillset, skill) -> {input name: value}."""
Locate = Callable[[Sequence[str]], Pos | None]
"""Where a path of keys (``("go_to_waypoint", "target")``) is written, if known."""

_INT_BITS = {"byte": (8, False), "char": (8, False), "octet": (8, False), "int8": (8, True), "uint8": (8, False),
             "int16": (16, True), "uint16": (16, False), "int32": (32, True), "uint32": (32, False),
             "int64": (64, True), "uint64": (64, False)}
_FLOATS = frozenset({"float32", "float64", "float128"})
_STRINGS = frozenset({"string", "wstring"})


def skill_named(system: System, key: str) -> tuple[str, Skill]:
    """The skill that ``key`` (``skill`` or ``skillset:skill``) names; ``ValueError`` with the candidates."""
    every = [(c.name, k) for c in system.components for k in c.skillset.skills]
    if ":" in key:
        found = [(ss, k) for ss, k in every if f"{ss}:{k.name}" == key]
    else:
        found = [(ss, k) for ss, k in every if k.name == key]
    if len(found) == 1:
        return found[0]
    if found:
        options = " or ".join(f"'{ss}:{k.name}'" for ss, k in found)
        raise ValueError(f"skill '{key}' is in several skillsets: write {options}")
    raise ValueError(unknown("skill", key, [f"{ss}:{k.name}" for ss, k in every if k.inputs]
                             + [k.name for _, k in every if k.inputs]))


def parse_inputs(system: System, table: object, source: str, locate: Locate | None = None,
                 types: Mapping[str, str] | None = None) -> Inputs:
    """Check an ``inputs`` table; ``types`` is the system's type map (``.rl`` type -> ROS type)."""
    where = locate or (lambda keys: None)
    if not isinstance(table, dict):
        raise SourceError.at(source, where(()), "inputs must be a table of skills, each a table of input values")
    out: Inputs = {}
    for key, values in table.items():
        try:
            skillset, skill = skill_named(system, key)
        except ValueError as exc:
            raise SourceError.at(source, where((key,)), str(exc)) from None
        name = f"{skillset}:{skill.name}"
        if (skillset, skill.name) in out:
            raise SourceError.at(source, where((key,)), f"inputs of {name} are given twice")
        if not isinstance(values, dict):
            raise SourceError.at(source, where((key,)), f"inputs of {name} must be a table of input values")
        declared = {v.name: v for v in skill.inputs}
        for field, value in values.items():
            if field not in declared:
                raise SourceError.at(source, where((key, field)), unknown("input", field, list(declared), f" of {name}"))
            problem = type_problem(value, declared[field], types or {})
            if problem:
                raise SourceError.at(source, where((key, field)),
                                     f"input '{field}' of {name} ({declared[field].type}): {problem}")
        out[(skillset, skill.name)] = dict(values)
    return out


def missing(skill: Skill, given: Mapping[str, Any] | None) -> list[Variable]:
    """The inputs of ``skill`` that ``given`` leaves out."""
    return [v for v in skill.inputs if v.name not in (given or {})]


def type_problem(value: Any, variable: Variable, types: Mapping[str, str]) -> str | None:
    """Why ``value`` cannot be ``variable``'s, or ``None`` (also when its type is unknown)."""
    ros = types.get(variable.type, variable.type)
    if "/" in ros:
        store = _store()
        name = ros if "/msg/" in ros else ros.replace("/", "/msg/", 1)
        if name not in store.fielddefs:
            return None  # a message the Humble store does not know: nothing to check against
        return _problem(value, (_NAME, name), store, "")
    base = ros.split("<=")[0]
    if base in _INT_BITS or base in _FLOATS or base in _STRINGS or base == "bool":
        return _problem(value, (_BASE, (base, 0)), None, "")
    return None


_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4  # rosbags' Nodetype values


def message_problem(value: Any, typename: str, store: Any) -> str | None:
    """Why ``value`` (a table of fields) cannot be a ``typename`` message of ``store``, or ``None``
    (a binding's goal fields, :mod:`skinet.ros.binding`)."""
    return _problem(value, (_NAME, typename), store, "")


@cache
def _store() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _kind(value: Any) -> str:
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    return type(value).__name__


def _problem(value: Any, desc: tuple[int, Any], store: Any, path: str) -> str | None:
    kind, arg = int(desc[0]), desc[1]
    at = f" at {path}" if path else ""
    if kind == _BASE:
        name = arg[0]
        if name == "bool":
            ok = isinstance(value, bool)
        elif name in _FLOATS:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        elif name in _STRINGS:
            ok = isinstance(value, str)
        elif name in _INT_BITS:
            bits, signed = _INT_BITS[name]
            low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
            if isinstance(value, int) and not isinstance(value, bool) and not low <= value <= high:
                return f"{value} is out of range for {name}{at} ({low} to {high})"
            ok = isinstance(value, int) and not isinstance(value, bool)
        else:
            return None
        return None if ok else f"expected {name}{at}, got {_kind(value)}"
    if kind == _NAME:
        if not isinstance(value, dict):
            return f"expected a table of the fields of {arg}{at}, got {_kind(value)}"
        fields = dict(store.fielddefs[arg][1])
        for field, sub in value.items():
            if field not in fields:
                return f"{arg} has no field '{field}'{at} (fields: {', '.join(fields)})"
            problem = _problem(sub, fields[field], store, f"{path}.{field}" if path else field)
            if problem:
                return problem
        return None
    sub_desc, length = arg
    if not isinstance(value, list):
        return f"expected a list{at}, got {_kind(value)}"
    if kind == _ARRAY and len(value) != length:
        return f"expected {length} elements{at}, got {len(value)}"
    for n, item in enumerate(value):
        problem = _problem(item, sub_desc, store, f"{path}[{n}]")
        if problem:
            return problem
    return None
