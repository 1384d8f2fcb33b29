"""CDR encoding and decoding of a skillset manager's messages with ``rosbags``.

:func:`build_typestore` starts from the ROS 2 Humble store (``std_msgs``,
``geometry_msgs``, ``builtin_interfaces``, ...) and registers every message of the
skillset's interface package under ``<package>/msg/<Name>``.

``rosbags`` (0.3-0.5 s to import) is imported by the functions that make a store,
not by this module: a process that never handles a ROS message never pays for it
(docs/performance.md); the functions given a store find it already imported.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, fields, is_dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from skinet.errors import Diagnostic, Pos, SourceError
from skinet.lang.model import Skillset
from skinet.ros.defaults import DefaultError, defaults_of, message_defaults, register
from skinet.ros.interfaces import typed_fields, generate_messages, package_name

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = [
    "Typestore",
    "build_typestore",
    "decode",
    "default_instance",
    "encode",
    "msg_typename",
    "ros_typename",
    "to_plain",
]


def msg_typename(skillset: Skillset | str, message: str) -> str:
    """Full type name of an interface message: ``isae_robot_skillset_interfaces/msg/DataPose``."""
    return f"{package_name(skillset)}/msg/{message}"


def ros_typename(ros_type: str) -> str:
    """``std_msgs/Float64`` -> ``std_msgs/msg/Float64``; full names and primitives unchanged."""
    parts = ros_type.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else ros_type


def build_typestore(
    skillset: Skillset,
    typemap: Mapping[str, str],
    extra: Mapping[str, str] | None = None,
) -> Typestore:
    """Humble store + the skillset's interface messages.

    ``extra`` maps full type names (``my_msgs/msg/Foo``) to ``.msg`` texts for ROS
    types the type map uses that the Humble store lacks.  A mapped ROS type that is
    neither a primitive nor known raises :class:`SourceError` at each use.
    """
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg
    from rosbags.typesys.base import BASE_NAMES

    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    defaults: dict[str, dict[str, Any]] = {}
    for name, text in (extra or {}).items():
        types.update(get_types_from_msg(text, name))
        try:
            defaults[name] = message_defaults(text)
        except DefaultError as exc:
            raise SourceError.at(f"<{name}>", Pos(exc.line, exc.column), str(exc)) from None
    pkg = package_name(skillset)
    for name, text in generate_messages(skillset, typemap).items():
        types.update(get_types_from_msg(text, f"{pkg}/msg/{name}"))
    known = store.fielddefs.keys() | types.keys()
    errors: list[Diagnostic] = []
    for var, where in typed_fields(skillset):
        ros = typemap[var.type]
        if "/" in ros:
            ok = ros_typename(ros) in known
        else:
            ok = ros.split("<=")[0] in BASE_NAMES
        if not ok:
            errors.append(
                Diagnostic(
                    skillset.source,
                    var.type_pos or var.pos,
                    "error",
                    f'type "{var.type}" maps to "{ros}", '
                    f"a ROS type the type store does not know ({where})",
                )
            )
    if errors:
        raise SourceError(errors)
    store.register(types)
    register(store, defaults)
    return store


def encode(store: Typestore, typename: str, obj: object) -> bytes:
    """CDR bytes (little endian, with the 4-byte header ``00 01 00 00``)."""
    return bytes(store.serialize_cdr(obj, typename, little_endian=True))


def decode(store: Typestore, typename: str, data: bytes | memoryview) -> Any:
    """Message object from CDR bytes (raises ``rosbags.serde.SerdeError`` on bad data)."""
    return store.deserialize_cdr(data, typename)


def _default(store: Typestore, desc: Any) -> Any:
    from rosbags.interfaces import Nodetype

    kind, arg = desc
    if kind == Nodetype.BASE:
        name = arg[0]
        if name == "string":
            return ""
        if name == "bool":
            return False
        if name.startswith("float"):
            return 0.0
        return 0
    if kind == Nodetype.NAME:
        return default_instance(store, arg)
    sub, length = arg
    if sub[0] == Nodetype.BASE and sub[1][0] != "string":
        dtype = {"bool": "bool_", "char": "uint8"}.get(sub[1][0], sub[1][0])  # as rosbags
        return np.zeros(length if kind == Nodetype.ARRAY else 0, dtype=dtype)
    if kind == Nodetype.ARRAY:
        return [_default(store, sub) for _ in range(length)]
    return []


def default_instance(store: Typestore, typename: str, **values: Any) -> Any:
    """An instance of ``typename`` with default fields, some replaced by ``values``.

    A field takes its definition's default value (:mod:`skinet.ros.defaults`), else:
    numbers are 0, strings empty, bools false, sequences empty, fixed arrays full of
    defaults, nested messages default.  An unknown field name raises ``TypeError``.
    """
    from rosbags.typesys.base import normalize_fieldname

    _, fielddefs = store.fielddefs[typename]
    cls = store.types[typename]
    args = {normalize_fieldname(name): _default(store, desc) for name, desc in fielddefs}
    for name, value in defaults_of(store, typename).items():
        name = normalize_fieldname(name)
        if name in args:
            args[name] = np.array(value, dtype=args[name].dtype) if isinstance(args[name], np.ndarray) else value
    unknown = set(values) - args.keys()
    if unknown:
        raise TypeError(f"{typename} has no field {', '.join(sorted(unknown))}")
    args.update(values)
    return cls(**args)


def to_plain(obj: Any) -> Any:
    """A message as nested dicts, lists and scalars (for comparison and JSON).

    Constants and the placeholder field of an empty message are left out.
    """
    if is_dataclass(obj) and not isinstance(obj, type):
        # Only constants and ``__msgtype__`` have defaults in rosbags' dataclasses.
        return {f.name: to_plain(getattr(obj, f.name)) for f in fields(obj) if f.default is MISSING}
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (list, tuple)):
        return [to_plain(x) for x in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def __getattr__(name: str) -> Any:
    """``Typestore`` (rosbags' store class, in ``__all__``), imported when first asked for."""
    if name == "Typestore":
        from rosbags.typesys.store import Typestore

        return Typestore
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
