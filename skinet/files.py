"""Reading model files from disk: the only module of the core that does I/O.

A *system file* (TOML) names the skillsets, the properties file and, for each
skillset, the ROS 2 node of its manager; paths are relative to the file::

    [system]
    name = "spot_arm"
    properties = "spot_arm.props"

    [[skillsets]]
    model = "spot.rl"
    manager = "/spot/spot_skillset_manager"

``[system] types = "spot_arm.types.json"`` names the type map (ONERA's JSON
format) that gives each ``.rl`` type its ROS 2 message; :func:`load_typemap`
reads it.
"""

from __future__ import annotations

import json
import re
import tomllib
from dataclasses import replace
from pathlib import Path

from skinet.errors import Diagnostic, Pos, SourceError
from skinet.lang.model import Model
from skinet.lang.parser import parse_model
from skinet.options import parse_prediction
from skinet.ros.typemap import TypeMap, parse_typemap
from skinet.system import Marking, System, build_system, marking_from_json


def read_text(path: str | Path) -> str:
    """File contents, or a :class:`SourceError` naming the file and the OS reason."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise SourceError.at(str(path), None, f"cannot read file: {reason}") from None


def load_model(path: str | Path) -> Model:
    """Parse and validate a ``.rl`` file."""
    return parse_model(read_text(path), str(path))


def load_system(path: str | Path) -> tuple[System, list[Diagnostic]]:
    """Load a system file and everything it names; returns the warnings too."""
    path = Path(path)
    text = read_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _toml_error(str(path), exc) from None
    where = str(path)
    system = data.get("system")
    if not isinstance(system, dict) or not isinstance(system.get("name"), str):
        raise SourceError.at(where, None, "missing [system] table with a 'name' string")
    entries = data.get("skillsets")
    if not isinstance(entries, list) or not entries:
        raise SourceError.at(where, None, "missing [[skillsets]] entries (each with 'model' and 'manager')")
    skillsets = []
    warnings: list[Diagnostic] = []
    sources: dict[str, str] = {}
    for n, entry in enumerate(entries, 1):
        if not isinstance(entry, dict) or not isinstance(entry.get("model"), str):
            raise SourceError.at(where, None, f"skillsets entry {n} needs a 'model' path")
        model_path = path.parent / entry["model"]
        model_text = read_text(model_path)
        model = parse_model(model_text, str(model_path))
        warnings.extend(model.warnings)
        if len(model.skillsets) != 1:
            raise SourceError.at(str(model_path), None, f"expected exactly one skillset, found {len(model.skillsets)}")
        skillset = model.skillsets[0]
        expected = entry.get("name")
        if expected is not None and expected != skillset.name:
            raise SourceError.at(where, None, f"skillsets entry {n} names '{expected}' but {entry['model']} declares '{skillset.name}'")
        sources[model_path.name] = model_text
        skillsets.append((skillset, str(entry.get("manager", ""))))
    props_name = system.get("properties")
    props_text, props_source = "", "<no properties>"
    if props_name is not None:
        props_path = path.parent / str(props_name)
        props_text, props_source = read_text(props_path), str(props_path)
        sources[props_path.name] = props_text
    built = build_system(system["name"], skillsets, props_text, props_source, sources)
    options = parse_prediction(data.get("prediction"), [p.name for p in built.properties], where, text)
    return replace(built, prediction=options), warnings


def load_typemap(path: str | Path) -> TypeMap:
    """The type map named by ``[system] types`` in a system file (empty when absent)."""
    path = Path(path)
    try:
        data = tomllib.loads(read_text(path))
    except tomllib.TOMLDecodeError as exc:
        raise _toml_error(str(path), exc) from None
    name = data.get("system", {}).get("types") if isinstance(data.get("system"), dict) else None
    if name is None:
        return {}
    if not isinstance(name, str):
        raise SourceError.at(str(path), None, "[system] 'types' must be a path string")
    types_path = path.parent / name
    return parse_typemap(read_text(types_path), str(types_path))


_UNITS = {"": 1, "b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9, "kib": 2**10, "mib": 2**20, "gib": 2**30}


def parse_size(text: str | int) -> int:
    """Bytes from ``"1 GiB"``, ``"512MiB"``, ``"2 GB"`` or a plain number of bytes."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([A-Za-z]*)\s*", str(text))
    unit = match.group(2).lower() if match else ""
    if not match or unit not in _UNITS or float(match.group(1)) * _UNITS[unit] < 1:
        raise ValueError(f"not a size: {text!r} (e.g. 1GiB, 512MiB, 2GB)")
    return int(float(match.group(1)) * _UNITS[unit])


def load_memory_limit(path: str | Path) -> int | None:
    """``[system] memory_limit`` of a system file (bytes; ``None`` when absent), SPEC §6.1."""
    path = Path(path)
    try:
        data = tomllib.loads(read_text(path))
    except tomllib.TOMLDecodeError as exc:
        raise _toml_error(str(path), exc) from None
    value = data.get("system", {}).get("memory_limit") if isinstance(data.get("system"), dict) else None
    if value is None:
        return None
    try:
        if isinstance(value, bool) or not isinstance(value, (int, str)):
            raise ValueError(f"not a size: {value!r} (e.g. \"1GiB\")")
        return parse_size(value)
    except ValueError as exc:
        raise SourceError.at(str(path), None, f"[system] memory_limit: {exc}") from None


def load_state(path: str | Path, system: System) -> Marking:
    """A combined marking from a JSON state file (see :func:`skinet.system.marking_from_json`)."""
    text = read_text(path)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SourceError.at(str(path), Pos(exc.lineno, exc.colno), f"invalid JSON: {exc.msg}") from None
    return marking_from_json(system, data, str(path))


def _toml_error(source: str, exc: tomllib.TOMLDecodeError) -> SourceError:
    match = re.search(r"\(at line (\d+), column (\d+)\)$", str(exc))
    message = re.sub(r"\s*\(at line \d+, column \d+\)$|\s*\(at end of document\)$", "", str(exc))
    pos = Pos(int(match.group(1)), int(match.group(2))) if match else None
    return SourceError.at(source, pos, f"invalid TOML: {message}")
