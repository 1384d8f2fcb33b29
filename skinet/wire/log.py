"""Monitor logs: JSON Lines, one object per message seen on Zenoh.

Each line is ``{"t": <receive time, s>, "key": "<zenoh key>", "type":
"<MessageName>", "message": <model_dump(mode="json")>}``.  ``skinet record``
writes them, ``skinet demo --log`` writes the same from the core replay, and
``skinet timeline`` draws them.  Pure helpers, no I/O.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass

from pydantic import BaseModel, ValidationError

from skinet.errors import Diagnostic, SourceError
from skinet.wire.messages import MESSAGES

FIELDS = ("t", "key", "type", "message")
MAX_ERRORS = 20  # diagnostics reported per log before giving up


@dataclass(frozen=True)
class Entry:
    """One logged message."""

    t: float  # receive time, seconds
    key: str  # Zenoh key the message was published on
    type: str  # message class name, a key of MESSAGES
    message: BaseModel


def log_line(key: str, message: BaseModel, t: float) -> str:
    """One log line (no trailing newline) for ``message`` received on ``key`` at ``t``."""
    name = type(message).__name__
    if MESSAGES.get(name) is not type(message):
        raise ValueError(f"'{name}' is not a wire message")
    return json.dumps({"t": t, "key": key, "type": name, "message": message.model_dump(mode="json")},
                      separators=(",", ":"), allow_nan=False)


def read_log(lines: Iterable[str], source: str = "<log>") -> list[Entry]:
    """Parse log lines (blank lines are skipped).

    Raises :class:`SourceError` whose diagnostics read ``FILE:LINE: error: ...``,
    one per malformed line (at most :data:`MAX_ERRORS`).
    """
    entries: list[Entry] = []
    errors: list[Diagnostic] = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        entry = _entry(line)
        if isinstance(entry, Entry):
            entries.append(entry)
            continue
        errors.append(Diagnostic(f"{source}:{n}", None, "error", entry))
        if len(errors) >= MAX_ERRORS:
            errors.append(Diagnostic(source, None, "error", f"too many errors, stopped at line {n}"))
            break
    if errors:
        raise SourceError(errors)
    return entries


def _entry(line: str) -> Entry | str:
    """The entry of one line, or the reason it is malformed."""
    try:
        data = json.loads(line)
    except json.JSONDecodeError as exc:
        return f"invalid JSON: {exc.msg} (column {exc.colno})"
    except RecursionError:
        return "invalid JSON: nested too deeply"
    if not isinstance(data, dict):
        return f"expected a JSON object, got {_json_type(data)}"
    for name in FIELDS:
        if name not in data:
            return f"missing field '{name}'"
    extra = sorted(set(data) - set(FIELDS))
    if extra:
        return f"unexpected field '{extra[0]}' (fields: {', '.join(FIELDS)})"
    t, key, kind, body = (data[f] for f in FIELDS)
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
        return f"field 't' must be a finite number, got {_json_type(t)}"
    if not isinstance(key, str):
        return f"field 'key' must be a string, got {_json_type(key)}"
    if not key:
        return "field 'key' is empty"
    if not isinstance(kind, str):
        return f"field 'type' must be a string, got {_json_type(kind)}"
    model = MESSAGES.get(kind)
    if model is None:
        return f"unknown message type '{kind}' (types: {', '.join(sorted(MESSAGES))})"
    if not isinstance(body, dict):
        return f"field 'message' must be an object, got {_json_type(body)}"
    try:
        message = model.model_validate(body)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(x) for x in first["loc"]) or "message"
        return f"invalid {kind}: {where}: {first['msg']}"
    return Entry(float(t), key, kind, message)


def _json_type(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, (int, float)):
        return "number" if not isinstance(value, float) or math.isfinite(value) else str(value)
    return {str: "string", list: "array", dict: "object"}.get(type(value), type(value).__name__)


__all__ = ["Entry", "MAX_ERRORS", "log_line", "read_log"]
