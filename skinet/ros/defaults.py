"""Default values of message fields, which ``rosbags`` reads and drops (docs/semantics.md §9).

A ``.msg`` field may carry a default (``float32 max_undocking_time 30.0``); ``rosidl``
gives it to every new message, and a goal the pilot sends through a binding must
too: Nav2 would time an undocking out at once with ``max_undocking_time`` 0.  This
module reads the defaults of a definition's text (every part of a ``.srv`` or an
``.action``: ``Name_Request``, ``Name_Goal``, ...) and knows the one non-zero default
of the standard messages a goal is likely to hold, a quaternion's ``w`` of 1
(``geometry_msgs/msg/Quaternion``, whose all-zero value is no rotation at all).
:func:`~skinet.ros.typestore.default_instance` applies them.

Only scalar primitive fields and arrays of numbers or booleans take a default, as in
ROS 2.  Pure; cost linear in the text's size.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any
from weakref import WeakKeyDictionary

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

Defaults = dict[str, dict[str, Any]]  # type name -> field -> value

STANDARD_DEFAULTS: Defaults = {"geometry_msgs/msg/Quaternion": {"w": 1.0}}

_FIELD = re.compile(r"\s*(?P<type>[a-z][a-z0-9]*)(?:<=\d+)?(?P<array>\[[^\]]*\])?\s+(?P<name>[a-z][a-z0-9_]*)\s+"
                    r"(?P<value>\S.*)$")
_NUMBERS = ("byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
            "uint64")
_registered: WeakKeyDictionary[Typestore, Defaults] = WeakKeyDictionary()


def _scalar(kind: str, text: str) -> Any:
    if kind == "bool":
        lowered = text.lower()
        if lowered not in ("true", "false", "1", "0"):
            raise ValueError(f"'{text}' is not a bool")
        return lowered in ("true", "1")
    if kind in ("string", "wstring"):
        return ast.literal_eval(text) if text[:1] in "'\"" else text
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError):
        raise ValueError(f"'{text}' is not a number") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"'{text}' is not a number")
    if kind.startswith("float"):
        return float(value)
    if not isinstance(value, int):
        raise ValueError(f"'{text}' is not an integer")
    return value


def _uncommented(line: str) -> str:
    quote = ""
    for i, c in enumerate(line):
        if quote:
            quote = "" if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == "#":
            return line[:i]
    return line


class DefaultError(ValueError):
    """A default its field's type cannot hold, at ``line`` and ``column`` (1-based) of its text."""

    def __init__(self, message: str, line: int, column: int):
        super().__init__(message)
        self.line, self.column = line, column


def message_defaults(text: str, first_line: int = 1) -> dict[str, Any]:
    """The defaults of one message's ``.msg`` text: field -> value (constants, ``NAME=VALUE``, are not fields).

    Raises :class:`DefaultError` for a default that its type cannot hold (lines counted from ``first_line``)."""
    out: dict[str, Any] = {}
    for number, line in enumerate(text.splitlines(), first_line):
        m = _FIELD.match(_uncommented(line).rstrip())
        if m is None or "=" in m["name"] or m["value"].startswith("="):
            continue
        kind, value = m["type"], m["value"].strip()
        if kind not in (*_NUMBERS, "bool", "string", "wstring"):
            continue
        try:
            if m["array"] is None:
                out[m["name"]] = _scalar(kind, value)
            elif value[:1] == "[" and value[-1:] == "]":
                out[m["name"]] = [_scalar(kind, x.strip()) for x in value[1:-1].split(",") if x.strip()]
            else:
                raise ValueError(f"'{value}' is not a list")
        except (ValueError, SyntaxError) as exc:
            raise DefaultError(f"the default of field {m['name']} ({kind}{m['array'] or ''}): {exc}", number,
                               m.start("value") + 1) from None
    return out


def definition_defaults(typename: str, parts: list[str]) -> Defaults:
    """The defaults of each message a definition gives (``parts``: its text split at ``---`` lines)."""
    kind = typename.split("/")[1]
    names = {"msg": [typename], "srv": [f"{typename}_Request", f"{typename}_Response"],
             "action": [f"{typename}_Goal", f"{typename}_Result", f"{typename}_Feedback"]}[kind]
    out: Defaults = {}
    line = 1
    for name, part in zip(names, parts, strict=True):
        found = message_defaults(part, line)
        if found:
            out[name] = found
        line += len(part.splitlines()) + 1  # and the '---' line
    return out


def register(store: Typestore, defaults: Mapping[str, Mapping[str, Any]]) -> None:
    """Add ``defaults`` to those :func:`defaults_of` gives for ``store``."""
    mine = _registered.setdefault(store, {})
    for name, fields in defaults.items():
        mine.setdefault(name, {}).update(fields)


def defaults_of(store: Typestore, typename: str) -> Mapping[str, Any]:
    """The non-zero defaults of ``typename``'s fields in ``store`` (the standard ones, then the registered)."""
    found = _registered.get(store, {}).get(typename)
    standard = STANDARD_DEFAULTS.get(typename)
    if found is None:
        return standard or {}
    return {**(standard or {}), **found}


__all__ = ["STANDARD_DEFAULTS", "DefaultError", "Defaults", "defaults_of", "definition_defaults", "message_defaults",
           "register"]
