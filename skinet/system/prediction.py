"""Prediction options of a system: which AF, forced constraints, events (docs/semantics.md §5, §6.2, §6.3).

Set in the system file's ``[prediction]`` table, for every property, and in
``[prediction.properties.NAME]`` for one property; the command line can
override them for all properties::

    [prediction]
    af = "fair"                      # or "literal" (the paper's AF, no fairness)
    forced = true                    # warn about forced constraints (docs/semantics.md §6.3)
    events_uncontrollable = false    # count events as uncontrollable steps too

    [prediction.properties.action_guard]
    af = "literal"

Examples:
    >>> opts = parse_prediction({"af": "literal"}, ["p"], "sys.toml")
    >>> opts.of("p").af
    'literal'
    >>> parse_prediction({"fair": True}, ["p"], "sys.toml")
    Traceback (most recent call last):
    ...
    skinet.errors.SourceError: sys.toml: error: [prediction] unknown option 'fair' (options: af, events_uncontrollable, forced)
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

from skinet.errors import Pos, SourceError

AF = Literal["fair", "literal"]
AF_MODES: tuple[str, ...] = ("fair", "literal")


@dataclass(frozen=True)
class PropertyOptions:
    """How one property is predicted."""

    af: AF = "fair"
    forced: bool = True
    events_uncontrollable: bool = False


OPTION_NAMES = tuple(sorted(PropertyOptions.__dataclass_fields__))


@dataclass(frozen=True)
class PredictionOptions:
    """Options for every property (``default``) and per property (``overrides``)."""

    default: PropertyOptions = PropertyOptions()
    overrides: Mapping[str, PropertyOptions] = field(default_factory=dict)

    def of(self, prop: str) -> PropertyOptions:
        return self.overrides.get(prop, self.default)

    def override(self, **values: object) -> "PredictionOptions":
        """The same options with ``values`` (those not None) set for every property."""
        given = {k: v for k, v in values.items() if v is not None}
        if not given:
            return self
        return PredictionOptions(replace(self.default, **given),
                                 {p: replace(o, **given) for p, o in self.overrides.items()})

    def af_modes(self, properties: Sequence[str]) -> dict[str, str]:
        return {p: self.of(p).af for p in properties}


def parse_prediction(
    table: object, properties: Sequence[str], source: str, text: str = ""
) -> PredictionOptions:
    """Check a ``[prediction]`` table (``text``, the file's text, only locates errors)."""
    if table is None:
        return PredictionOptions()
    if not isinstance(table, dict):
        raise SourceError.at(source, _locate(text, "prediction"), "[prediction] must be a table")
    per = table.get("properties", {})
    default = _property_options(
        {k: v for k, v in table.items() if k != "properties"}, PropertyOptions(), "[prediction]", source, text)
    if not isinstance(per, dict):
        raise SourceError.at(source, _locate(text, "properties"), "[prediction] 'properties' must be a table of tables")
    overrides = {}
    for name, values in per.items():
        if name not in properties:
            known = ", ".join(properties) or "none"
            raise SourceError.at(source, _locate(text, name),
                                 f"[prediction.properties] unknown property '{name}' (properties: {known})")
        if not isinstance(values, dict):
            raise SourceError.at(source, _locate(text, name), f"[prediction.properties.{name}] must be a table")
        overrides[name] = _property_options(values, default, f"[prediction.properties.{name}]", source, text)
    return PredictionOptions(default, overrides)


def _property_options(values: dict, base: PropertyOptions, where: str, source: str, text: str) -> PropertyOptions:
    out = base
    for key, value in values.items():
        pos = _locate(text, key)
        if key not in OPTION_NAMES:
            raise SourceError.at(source, pos, f"{where} unknown option '{key}' (options: {', '.join(OPTION_NAMES)})")
        if key == "af":
            if value not in AF_MODES:
                raise SourceError.at(source, pos, f"{where} af must be \"fair\" or \"literal\", not {value!r}")
        elif not isinstance(value, bool):
            raise SourceError.at(source, pos, f"{where} {key} must be true or false, not {value!r}")
        out = replace(out, **{key: value})
    return out


def _locate(text: str, key: str) -> Pos | None:
    """Where ``key = ...`` (or ``[...key]``) first appears in ``text``, if it does."""
    for n, line in enumerate(text.splitlines(), 1):
        m = re.search(rf"(^\s*|[.\[]){re.escape(key)}\s*(=|\])", line)
        if m:
            return Pos(n, m.start() + len(m.group(1)) + 1)
    return None
