"""Type maps: which ROS 2 type stands for each type name of a ``.rl`` model.

ONERA's format (``isae_robot.json``)::

    {"type": [{"name": "Float", "package": "std_msgs", "message": "Float64"}, ...]}

An entry may give ``"idl": "float64"`` (a ROS primitive type) instead of
``package`` and ``message``, as older ONERA files do.  Other keys are ignored.
"""

from __future__ import annotations

import json
import re

from skinet.errors import Pos, SourceError

TypeMap = dict[str, str]
"""rl type name -> ROS type as written in a ``.msg`` file (``std_msgs/Float64``)."""


def parse_typemap(text: str, source: str = "<typemap>") -> TypeMap:
    """Parse a type-map JSON text; raise :class:`SourceError` on any defect."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise SourceError.at(source, Pos(e.lineno, e.colno), f"malformed JSON: {e.msg}") from None
    except RecursionError:
        raise SourceError.at(source, None, "malformed JSON: nested too deeply") from None
    if not isinstance(doc, dict):
        raise SourceError.at(source, None, 'a type map must be a JSON object with a "type" list')
    if "type" not in doc:
        raise SourceError.at(source, None, 'missing key "type"')
    entries = doc["type"]
    if not isinstance(entries, list):
        raise SourceError.at(source, None, '"type" must be a list')
    result: TypeMap = {}
    for i, entry in enumerate(entries, 1):
        where = f"type entry {i}"
        if not isinstance(entry, dict):
            raise SourceError.at(source, None, f"{where} must be an object")
        name = _string(entry, "name", where, source)
        where = f'{where} ("{name}")'
        if "idl" in entry and "package" not in entry and "message" not in entry:
            ros = _string(entry, "idl", where, source)
        else:
            package = _string(entry, "package", where, source)
            message = _string(entry, "message", where, source)
            ros = f"{package}/{message}"
        if name in result:
            raise SourceError.at(source, None, f'{where}: duplicate type name "{name}"')
        result[name] = ros
    return result


_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_IDL = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(<=[0-9]+)?")


def _string(entry: dict[str, object], key: str, where: str, source: str) -> str:
    if key not in entry:
        raise SourceError.at(source, None, f'{where}: missing key "{key}"')
    value = entry[key]
    if not isinstance(value, str):
        raise SourceError.at(source, None, f'{where}: "{key}" must be a string')
    if not (_IDL if key == "idl" else _IDENT).fullmatch(value):
        raise SourceError.at(source, None, f'{where}: "{key}" is not a valid name: "{value}"')
    return value
