"""msgpack encoding of messages, with errors that never escape as crashes."""

from __future__ import annotations

from typing import TypeVar

import msgpack
from pydantic import BaseModel, ValidationError

from skinet.wire.messages import SCHEMA_VERSION

M = TypeVar("M", bound=BaseModel)


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected type."""


def encode(message: BaseModel) -> bytes:
    """msgpack of ``message``'s JSON form, without the later fields that hold their default
    (``OMIT_AT_DEFAULT``, :mod:`skinet.wire.messages`)."""
    data = message.model_dump(mode="json")
    fields = type(message).model_fields
    for name in getattr(message, "OMIT_AT_DEFAULT", ()):
        if getattr(message, name) == fields[name].get_default(call_default_factory=True):
            del data[name]
    return msgpack.packb(data, use_bin_type=True)


def decode(payload: bytes, kind: type[M]) -> M:
    """Decode ``payload`` as ``kind``; raises :class:`DecodeError` with a one-line reason."""
    try:
        data = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises several unrelated types
        raise DecodeError(f"not msgpack: {str(exc) or type(exc).__name__}") from None
    return validate(data, kind)


def validate(data: object, kind: type[M]) -> M:
    """``data``, an unpacked payload (or a message within one, e.g. :class:`~skinet.wire.messages.ResultFeed`'s),
    as ``kind``; raises :class:`DecodeError` with a one-line reason."""
    if not isinstance(data, dict):
        raise DecodeError(f"expected a map, got {type(data).__name__}")
    version = data.get("v")
    if type(version) is not int or version != SCHEMA_VERSION:  # not True, not 1.0
        raise DecodeError(f"unsupported schema version {version!r} (expected {SCHEMA_VERSION})")
    try:
        return kind.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(x) for x in first["loc"]) or "message"
        raise DecodeError(f"invalid {kind.__name__}: {where}: {first['msg']}") from None
