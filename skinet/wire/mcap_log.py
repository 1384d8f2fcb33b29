"""Monitor logs in MCAP (https://mcap.dev), for Foxglove and other robotics tools.

The same content as the JSON Lines logs of :mod:`skinet.wire.log`: one MCAP
*channel* per Zenoh key (topic = the key, message encoding ``json``), one
*schema* per message type (name = the type, encoding ``jsonschema``, data = the
JSON Schema of ``schemas/``), each message the JSON of ``model_dump(mode="json")``
with its receive time as ``log_time`` and ``publish_time`` (nanoseconds).
The caller opens and closes the binary streams (no file access here).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from typing import IO, Any

from pydantic import BaseModel, ValidationError

from skinet.errors import Diagnostic, SourceError
from skinet.files import program
from skinet.wire.log import MAX_ERRORS, Entry
from skinet.wire.messages import MESSAGES
from skinet.wire.schemas import schema

MAGIC = b"\x89MCAP0\r\n"
PROFILE = ""  # not a ROS profile: JSON messages with JSON schemas
LIBRARY = "skinet-live"
CHUNK_SIZE = 64 * 1024  # a recorder killed without warning loses at most this much


def rosbag_refused() -> str:
    """The one line that refuses a rosbag2 where a monitor log is read, and names the command that reads it."""
    return (f"this is a ROS 2 bag (rosbag2: CDR messages), not a monitor log: `{program.skinet()} conform SYSTEM BAG` "
            "checks a bag against a model")


def is_mcap(head: bytes) -> bool:
    """Whether a file starting with ``head`` is MCAP."""
    return head.startswith(MAGIC)


class McapLogWriter:
    """Writes log entries to a binary stream as MCAP; call :meth:`finish` at the end."""

    def __init__(self, stream: IO[bytes]):
        from mcap.writer import CompressionType, Writer

        self._writer = Writer(stream, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence = 0

    def write(self, key: str, message: BaseModel, t: float) -> None:
        name = type(message).__name__
        if MESSAGES.get(name) is not type(message):
            raise ValueError(f"'{name}' is not a wire message")
        schema_id = self._schemas.get(name)
        if schema_id is None:
            data = json.dumps(schema(type(message)), sort_keys=True).encode()
            schema_id = self._schemas[name] = self._writer.register_schema(name, "jsonschema", data)
        channel_id = self._channels.get(key)
        if channel_id is None:
            channel_id = self._channels[key] = self._writer.register_channel(key, "json", schema_id)
        self._sequence += 1
        stamp = int(t * 1e9)
        self._writer.add_message(channel_id, log_time=stamp, publish_time=stamp, sequence=self._sequence,
                                 data=json.dumps(message.model_dump(mode="json"), separators=(",", ":")).encode())

    def finish(self) -> None:
        self._writer.finish()


def read_mcap(stream: IO[bytes], source: str = "<log>", warn: Callable[[str], None] | None = None) -> list[Entry]:
    """The entries of an MCAP monitor log, in log-time order.

    Read front to back, so the complete chunks of an unfinished file (a recorder
    killed without warning) are kept: ``warn`` is told where the file ends.
    Raises :class:`SourceError` (``FILE: error: ...``) for a file with no readable
    message and for messages that are not valid wire messages (at most
    :data:`MAX_ERRORS`).
    """
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    entries: list[Entry] = []
    errors: list[Diagnostic] = []
    try:
        for mschema, channel, message in NonSeekingReader(stream).iter_messages(log_time_order=False):
            if channel.message_encoding == "cdr":  # one line for the whole bag, not one per message
                raise SourceError([Diagnostic(source, None, "error", rosbag_refused())])
            if channel.topic.startswith("/skinet/"):  # an incident bundle's Foxglove channels (a view of the rest)
                continue
            problem = _entry(mschema, channel, message, entries)
            if problem:
                errors.append(Diagnostic(f"{source}: message {message.sequence} on {channel.topic}", None, "error",
                                         problem))
                if len(errors) >= MAX_ERRORS:
                    break
    except (McapError, EOFError, ValueError, KeyError, struct.error) as exc:
        reason = str(exc) or type(exc).__name__
        if not entries or errors:
            errors.append(Diagnostic(source, None, "error", f"not a readable MCAP file after {len(entries)} "
                                                             f"messages: {reason}"))
        elif warn is not None:
            warn(f"{source}: warning: the MCAP file ends early (recorder stopped without finishing it?): "
                 f"read {len(entries)} messages ({reason})")
    if errors:
        raise SourceError(errors)
    entries.sort(key=lambda e: e.t)
    return entries


def _entry(mschema: Any, channel: Any, message: Any, out: list[Entry]) -> str | None:
    """Append the entry of one MCAP message to ``out``, or say why it is not one."""
    if mschema is None or channel.message_encoding != "json":
        return f"channel {channel.topic} is not JSON with a schema (encoding '{channel.message_encoding}')"
    model = MESSAGES.get(mschema.name)
    if model is None:
        return f"unknown message type '{mschema.name}' (types: {', '.join(sorted(MESSAGES))})"
    try:
        body = json.loads(message.data)
        parsed = model.model_validate(body)
    except json.JSONDecodeError as exc:
        return f"invalid JSON: {exc.msg}"
    except ValidationError as exc:
        first = exc.errors()[0]
        return f"invalid {mschema.name}: {'.'.join(str(x) for x in first['loc']) or 'message'}: {first['msg']}"
    out.append(Entry(message.log_time / 1e9, channel.topic, mschema.name, parsed))
    return None
