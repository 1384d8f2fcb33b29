"""Loading a system and what it names from disk (models, properties, bindings, types, goals, states).

Files are read through :mod:`skinet.files.read` (opened once, checked on the descriptor).

A *system file* (TOML) names the skillsets, the properties file and, for each
skillset, the ROS 2 node of its manager; paths are relative to the file::

    [system]
    name = "spot_arm"
    properties = "spot_arm.props"

    [[skillsets]]
    model = "spot.rl"
    manager = "/spot/spot_skillset_manager"

A skillset without a manager may name a *binding* instead (docs/semantics.md §9), a TOML file
mapping its skills, resources and events to plain ROS 2 action servers,
lifecycle nodes and topics: ``binding = "nav2.binding.toml"`` (read by
:func:`load_bindings`).

``[system] types = "spot_arm.types.json"`` names the type map (ONERA's JSON
format) that gives each ``.rl`` type its ROS 2 message; :func:`load_typemap`
reads it.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from skinet.files.read import FileRefused, read_bytes, read_source, utf8_text
from skinet.errors import Diagnostic, Pos, SourceError, shown
from skinet.lang.larkerrors import MAX_SOURCE_CHARS
from skinet.lang.model import Model, Skillset
from skinet.lang.parser import link, parse_unit
from skinet.system.prediction import parse_prediction
from skinet.ros.binding import Binding, commanded_events, definitions_folder, lifecycle_events, parse_binding
from skinet.ros.definitions import KINDS
from skinet.ros.typemap import TypeMap, parse_typemap
from skinet.files.toml import check_keys, check_tables, locate, parse_toml
from skinet.system.model import Marking, System, build_system, marking_from_json, marking_problems

if TYPE_CHECKING:
    from skinet.plan.goal import Goal


# The folder that included files must lie in, when not the model's own (issue 25).
INCLUDE_ROOT_ENV = "SKINET_INCLUDE_ROOT"


def load_model(path: str | Path, include_root: str | Path | None = None) -> Model:
    """Parse and validate a ``.rl`` file, with the files it includes (see :func:`_load_linked`)."""
    return _load_linked(Path(path), include_root)[0]


def _load_linked(path: Path, include_root: str | Path | None = None) -> tuple[Model, dict[str, str]]:
    """A model file linked with every file it includes, and each file's text by source.

    ``include "name"`` is relative to the including file; each file is parsed once
    (so include cycles end), known by the device and inode of what was opened.
    Included files must lie, symbolic links resolved, inside ``include_root``
    (default: ``$SKINET_INCLUDE_ROOT``, else the model file's folder), and be
    regular files, checked on the open descriptor (:func:`read_bytes`); their
    syntax errors give the position but quote no text, so an include can never
    show what another file holds, and an error shows at most
    :data:`skinet.errors.MAX_SHOWN` characters of a name.
    """
    data, st = _read_source_bytes(path, None)
    text = utf8_text(data, str(path))
    units = [parse_unit(text, str(path))]
    texts = {str(path): text}
    seen = {(st.st_dev, st.st_ino)}
    root = Path(include_root or os.environ.get(INCLUDE_ROOT_ENV) or path.parent).resolve()
    i = 0
    while i < len(units):
        including = Path(units[i][0].source)
        i += 1
        for name, pos in units[i - 1][0].includes:
            target = including.parent / name
            try:
                data, st = _read_source_bytes(target, root)
            except FileRefused as exc:
                reason = exc.reason
                if reason.startswith("it lies outside"):
                    reason += f" (included files stay in the model's folder, or in ${INCLUDE_ROOT_ENV})"
                raise SourceError.at(str(including), pos, f"cannot include '{shown(name)}': {reason}") from None
            if (st.st_dev, st.st_ino) in seen:  # the identity of what was opened: a cycle ends
                continue
            seen.add((st.st_dev, st.st_ino))
            try:
                included = utf8_text(data, str(target))
            except SourceError as exc:
                raise SourceError.at(str(including), pos,
                                     f"cannot include '{shown(name)}': {exc.diagnostics[0].message}") from None
            units.append(parse_unit(included, str(target), library=True))
            texts[str(target)] = included
    return link(units), texts


def _read_source_bytes(path: Path, root: Path | None) -> tuple[bytes, os.stat_result]:
    """:func:`read_bytes` of a source file (at most MAX_SOURCE_CHARS bytes); a refused
    top-level file is a :class:`SourceError` naming it, a refused include a :class:`FileRefused`."""
    if root is not None:
        return read_bytes(path, MAX_SOURCE_CHARS, root)
    try:
        return read_bytes(path, MAX_SOURCE_CHARS)
    except FileRefused as exc:
        raise SourceError.at(str(path), None, exc.reason) from None


SYSTEM_TABLES = ("[system]", "[[skillsets]]", "[prediction]")
SYSTEM_KEYS = ("name", "properties", "types", "memory_limit")
SKILLSET_KEYS = ("model", "manager", "name", "binding")


def load_system(path: str | Path) -> tuple[System, list[Diagnostic]]:
    """Load a system file and everything it names; returns the warnings too.

    Strict: an unknown table or key, or a value of the wrong kind, is an error at
    its position (a misspelt ``properties`` would leave the system with none).
    """
    path = Path(path)
    text = read_source(path)
    data = parse_toml(text, str(path))
    where = str(path)
    check_tables(data, SYSTEM_TABLES, where, text)
    system = data.get("system")
    if not isinstance(system, dict) or not isinstance(system.get("name"), str):
        raise SourceError.at(where, locate(text, ("system",)), "missing [system] table with a 'name' string")
    check_keys(system, SYSTEM_KEYS, where, text, ("system",), "[system]")
    for key in ("properties", "types"):
        _check_string(system, key, where, text, ("system",), "[system]")
    _memory_limit(system, where, text)
    entries = data.get("skillsets")
    if not isinstance(entries, list) or not entries:
        raise SourceError.at(where, None, "missing [[skillsets]] entries (each with 'model' and 'manager')")
    skillsets: list[tuple[Skillset, str, str]] = []
    commanded: dict[str, frozenset[str]] = {}  # skillset -> events its binding says are commanded
    commandable: dict[str, frozenset[str]] = {}  # skillset -> events that change a lifecycle node's resource
    warnings: list[Diagnostic] = []
    sources: dict[str, str] = {}
    models: dict[Path, tuple[Model, dict[str, str]]] = {}
    for n, entry in enumerate(entries, 1):
        if not isinstance(entry, dict) or not isinstance(entry.get("model"), str):
            raise SourceError.at(where, locate(text, ("skillsets", n - 1)),
                                 f"skillsets entry {n} needs a 'model' path")
        table, label = ("skillsets", n - 1), f"[[skillsets]] entry {n}"
        check_keys(entry, SKILLSET_KEYS, where, text, table, label)
        for key in ("manager", "name", "binding"):
            _check_string(entry, key, where, text, table, label)
        model_path = path.parent / entry["model"]
        if model_path not in models:
            models[model_path] = _load_linked(model_path)
            warnings.extend(models[model_path][0].warnings)
        model, texts = models[model_path]
        binding = _entry_binding(entry, path, text, table, label)
        for ss in _entry_skillsets(entry, n, model, where):
            skillsets.append((ss, str(entry.get("manager", "")), binding))
            sources[Path(ss.source).name] = texts[ss.source]
            if binding:  # its commanded resources make events controllable (docs/semantics.md §9); load_bindings checks the rest
                binding_text = read_source(Path(binding))
                commanded[ss.name] = commanded_events(binding_text, binding, ss)
                commandable[ss.name] = lifecycle_events(binding_text, binding, ss)
    props_name = system.get("properties")
    props_text, props_source = "", "<no properties>"
    if props_name is not None:
        props_path = path.parent / str(props_name)
        props_text, props_source = read_source(props_path), str(props_path)
        sources[props_path.name] = props_text
    built = build_system(system["name"], skillsets, props_text, props_source, sources, commanded=commanded,
                         commandable=commandable)
    options = parse_prediction(data.get("prediction"), [p.name for p in built.properties], where, text)
    return replace(built, prediction=options), warnings


def _check_string(table: dict[str, object], key: str, source: str, text: str, at: tuple[str | int, ...],
                  label: str) -> None:
    """A key that, when given, must be a string (a path or a name)."""
    value = table.get(key)
    if value is not None and not isinstance(value, str):
        raise SourceError.at(source, locate(text, at, key), f"{label} '{key}' must be a string, not {value!r}")


def _entry_binding(entry: dict[str, object], path: Path, text: str, table: tuple[str | int, ...],
                   label: str) -> str:
    """The binding file of a ``[[skillsets]]`` entry, relative to the system file ('' when none)."""
    binding = entry.get("binding")
    if binding is None:
        return ""
    if "manager" in entry:
        raise SourceError.at(str(path), locate(text, table, "binding"),
                             f"{label}: give 'manager' (a skillset manager) or 'binding' (plain ROS 2 interfaces), "
                             "not both")
    return str(path.parent / str(binding))


def _entry_skillsets(entry: dict[str, object], n: int, model: Model, where: str) -> list[Skillset]:
    """The skillsets a ``[[skillsets]]`` entry takes from its model file.

    ``name`` picks one skillset of the file; without it the entry takes every
    skillset the file declares (one manager each, so ``manager`` then needs a
    file of one skillset).
    """
    declared = ", ".join(f"'{s.name}'" for s in model.skillsets)
    expected = entry.get("name")
    if expected is not None:
        for ss in model.skillsets:
            if ss.name == expected:
                return [ss]
        raise SourceError.at(where, None, f"skillsets entry {n} names '{shown(str(expected))}' but "
                             f"{shown(str(entry['model']))} declares {declared}")
    if len(model.skillsets) > 1 and ("manager" in entry or "binding" in entry):
        raise SourceError.at(
            where, None,
            f"skillsets entry {n}: {shown(str(entry['model']))} declares {len(model.skillsets)} skillsets ({declared});"
            " give one entry per skillset, each with its 'name' and 'manager'",
        )
    return list(model.skillsets)


def load_goals(path: str | Path, system: System, types: Mapping[str, str] | None = None) -> list[Goal]:
    """A goals file (a mission, docs/semantics.md §8): see :mod:`skinet.plan.goalfile`; ``types``: the system's type map."""
    from skinet.plan.goalfile import parse_goals

    return parse_goals(read_source(path), system, str(path), types)


def load_typemap(path: str | Path) -> TypeMap:
    """The type map named by ``[system] types`` in a system file (empty when absent)."""
    path = Path(path)
    data = parse_toml(read_source(path), str(path))
    name = data.get("system", {}).get("types") if isinstance(data.get("system"), dict) else None
    if name is None:
        return {}
    if not isinstance(name, str):
        raise SourceError.at(str(path), None, "[system] 'types' must be a path string")
    types_path = path.parent / name
    return parse_typemap(read_source(types_path), str(types_path))


def load_bindings(system: System) -> tuple[dict[str, Binding], list[Diagnostic]]:
    """The binding of every skillset of ``system`` that names one (docs/semantics.md §9), and their warnings.

    A binding's ``definitions`` folder (relative to the binding file) holds
    ``<package>/<msg|srv|action>/<Name>.<msg|srv|action>`` files; each is read and
    registered as ``<package>/<kind>/<Name>``.
    """
    bindings: dict[str, Binding] = {}
    warnings: list[Diagnostic] = []
    for c in system.components:
        if not c.binding:
            continue
        path = Path(c.binding)
        text = read_source(path)
        folder = definitions_folder(text, str(path))
        texts, sources = _read_definitions(path.parent / folder, str(path)) if folder else ({}, {})
        bindings[c.name] = parse_binding(text, str(path), c.skillset, texts, sources)
        warnings.extend(bindings[c.name].warnings)
    return bindings, warnings


def _read_definitions(folder: Path, binding: str) -> tuple[dict[str, str], dict[str, str]]:
    """Every definition file below ``folder`` by type name, and the file of each; each
    must lie, links resolved, inside the folder (:func:`read_bytes` checks what it opened)."""
    if not folder.is_dir():
        raise SourceError.at(binding, None, f"definitions folder {shown(str(folder))} is not a folder")
    root = folder.resolve()
    texts: dict[str, str] = {}
    sources: dict[str, str] = {}
    for kind in KINDS:
        for file in sorted(folder.glob(f"*/{kind}/*.{kind}")):
            name = f"{file.parent.parent.name}/{kind}/{file.stem}"
            texts[name], sources[name] = read_source(file, root), str(file)
    return texts, sources


_UNITS = {"": 1, "b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9, "kib": 2**10, "mib": 2**20, "gib": 2**30}


def parse_size(text: str | int) -> int:
    """Bytes from ``"1 GiB"``, ``"512MiB"``, ``"2 GB"`` or a plain number of bytes."""
    if str(text).strip().startswith("-"):
        raise ValueError(f"not a size: {text!r} (a size is positive, e.g. 1GiB, 512MiB, 2GB)")
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([A-Za-z]*)\s*", str(text))
    unit = match.group(2).lower() if match else ""
    if not match or unit not in _UNITS or float(match.group(1)) * _UNITS[unit] < 1:
        raise ValueError(f"not a size: {text!r} (e.g. 1GiB, 512MiB, 2GB)")
    return int(float(match.group(1)) * _UNITS[unit])


def load_memory_limit(path: str | Path) -> int | None:
    """``[system] memory_limit`` of a system file (bytes; ``None`` when absent), docs/semantics.md §6.1."""
    path = Path(path)
    text = read_source(path)
    data = parse_toml(text, str(path))
    return _memory_limit(data.get("system"), str(path), text)


def _memory_limit(system: object, source: str, text: str) -> int | None:
    value = system.get("memory_limit") if isinstance(system, dict) else None
    if value is None:
        return None
    try:
        if isinstance(value, bool) or not isinstance(value, (int, str)):
            raise ValueError(f"not a size: {value!r} (e.g. \"1GiB\")")
        return parse_size(value)
    except ValueError as exc:
        raise SourceError.at(source, locate(text, ("system",), "memory_limit"), f"[system] memory_limit: {exc}") from None


def load_state(path: str | Path, system: System, what_if: bool = False) -> Marking:
    """A combined marking from a JSON state file (see :func:`parse_state`)."""
    return parse_state(read_source(path), str(path), system, what_if)


def parse_state(text: str, source: str, system: System, what_if: bool = False) -> Marking:
    """A combined marking from JSON text (see :func:`skinet.system.model.marking_from_json`).

    A marking the live system cannot be in (see :func:`skinet.system.model.marking_problems`)
    is refused unless ``what_if``.
    """
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SourceError.at(source, Pos(exc.lineno, exc.colno), f"invalid JSON: {exc.msg}") from None
    except RecursionError:
        raise SourceError.at(source, None, "invalid JSON: nested too deeply") from None
    marking = marking_from_json(system, data, source)
    problems = [] if what_if else marking_problems(system, marking)
    if problems:
        raise SourceError.at(
            source, None,
            "impossible state: " + "; ".join(problems) + " (use --what-if to analyse it anyway)",
        )
    return marking
