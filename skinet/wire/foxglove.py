"""The Foxglove channels of a monitored system: topics, schema names and JSON Schemas (docs/foxglove.md).

``skinet foxglove`` serves these channels live over the ``foxglove.websocket.v1``
protocol; an incident bundle (MCAP) holds the same ones, so a bundle opens in
Foxglove as the live run did.  Every channel is JSON-encoded.  The monitor's own
messages keep their wire shape (their JSON Schemas are the pydantic models'
own, as in schemas/); the others are small shapes of this module:

* ``/skinet/violations``: one message per property going from holding to failing;
* ``/skinet/divergences``: one message per model divergence or manager restart;
* ``/skinet/series``: the numbers a Plot panel draws, one message per step;
* ``/skinet/log``: ``foxglove.Log`` lines (one per step, per warning, per pilot change).

Pure data, no I/O.  Cost: the schemas are built once per call of :func:`channels` (O(size of the models)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from skinet.wire.messages import Divergence, LiveState, PilotStatus, StateSpaceReport, UnsafeReport, Verdicts

STATE, VERDICTS, UNSAFE = "/skinet/state", "/skinet/verdicts", "/skinet/unsafe"
VIOLATIONS, DIVERGENCES, STATE_SPACE = "/skinet/violations", "/skinet/divergences", "/skinet/state_space"
PILOT, LOG, SERIES = "/skinet/pilot", "/skinet/log", "/skinet/series"

# foxglove.Log's levels (the Log panel's colours)
DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5


@dataclass(frozen=True)
class ChannelSpec:
    """One channel: its topic, schema name and JSON Schema."""

    topic: str
    schema_name: str
    schema: dict[str, Any]


def _object(properties: dict[str, Any], title: str, description: str) -> dict[str, Any]:
    return {"type": "object", "title": title, "description": description, "properties": properties,
            "required": sorted(properties)}


_NUMBER, _INT, _STR, _BOOL = {"type": "number"}, {"type": "integer"}, {"type": "string"}, {"type": "boolean"}
_TIME = _object({"sec": _INT, "nsec": _INT}, "time", "seconds and nanoseconds since the epoch")

VIOLATION_SCHEMA = _object(
    {"n": _INT, "property": _STR, "seq": _INT, "epoch": _INT, "event": _STR, "t": _NUMBER, "joined": _BOOL},
    "skinet.Violation",
    "A property went from holding to failing at monitor step `seq` (event `event`); `joined`: it was already "
    "violated when this view joined, so its onset is not known here.")
DIVERGENCE_SCHEMA = {**Divergence.model_json_schema(), "title": "skinet.Divergence"}
DIVERGENCE_SCHEMA["properties"] = {"monitor": _STR, **DIVERGENCE_SCHEMA["properties"]}
SERIES_SCHEMA = _object(
    {"seq": _INT, "violated": _INT, "violations": _INT, "unsafe": _INT, "literal": _INT,
     "prediction_stale": _BOOL, "prediction_age": _NUMBER, "divergences": _INT},
    "skinet.Series",
    "Numbers per step for a Plot panel: properties violated now, violations so far, unsafe commands, the literal "
    "list's size, whether the prediction is stale and its age in seconds (since the last fresh one), "
    "divergences and manager restarts so far.")
LOG_SCHEMA = _object(
    {"timestamp": _TIME, "level": {"type": "integer", "minimum": 0, "maximum": 5}, "message": _STR, "name": _STR,
     "file": _STR, "line": {"type": "integer", "minimum": 0}},
    "foxglove.Log", "A log line (level 1 debug, 2 info, 3 warning, 4 error, 5 fatal).")


def _model(model: type, name: str) -> dict[str, Any]:
    return {**model.model_json_schema(), "title": name}


def channels() -> list[ChannelSpec]:
    """Every channel, in the order they are advertised."""
    return [
        ChannelSpec(STATE, "skinet.LiveState", _model(LiveState, "skinet.LiveState")),
        ChannelSpec(VERDICTS, "skinet.Verdicts", _model(Verdicts, "skinet.Verdicts")),
        ChannelSpec(UNSAFE, "skinet.UnsafeReport", _model(UnsafeReport, "skinet.UnsafeReport")),
        ChannelSpec(VIOLATIONS, "skinet.Violation", VIOLATION_SCHEMA),
        ChannelSpec(DIVERGENCES, "skinet.Divergence", DIVERGENCE_SCHEMA),
        ChannelSpec(STATE_SPACE, "skinet.StateSpaceReport", _model(StateSpaceReport, "skinet.StateSpaceReport")),
        ChannelSpec(PILOT, "skinet.PilotStatus", _model(PilotStatus, "skinet.PilotStatus")),
        ChannelSpec(SERIES, "skinet.Series", SERIES_SCHEMA),
        ChannelSpec(LOG, "foxglove.Log", LOG_SCHEMA),
    ]


def nanoseconds(t: float) -> int:
    """Seconds since the epoch as integer nanoseconds (MCAP and Foxglove log times)."""
    return int(round(t * 1e9))


def log_line(t: float, level: int, message: str, name: str) -> dict[str, Any]:
    """A ``foxglove.Log`` message at ``t`` (seconds since the epoch)."""
    ns = nanoseconds(t)
    return {"timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}, "level": level,
            "message": message, "name": name, "file": "", "line": 0}


__all__ = ["ChannelSpec", "channels", "log_line", "nanoseconds", "STATE", "VERDICTS", "UNSAFE", "VIOLATIONS",
           "DIVERGENCES", "STATE_SPACE", "PILOT", "LOG", "SERIES"]
