"""Incident bundles: one MCAP file to see and re-run a stretch of a monitored run (docs/foxglove.md).

A bundle holds:

* the monitor's wire messages as :mod:`skinet.wire.mcap_log` writes them (topic
  = the Zenoh key: canonical events as the monitor received them, states,
  verdicts, unsafe reports, divergences, the pilot's statuses), which
  ``skinet replay --verify`` re-runs;
* the same run on the channels of :mod:`skinet.wire.foxglove` (topics
  ``/skinet/...``), so that it opens in Foxglove as the live connection showed it;
* the model as attachments: ``model.json`` (the monitor's :class:`ModelBundle`),
  each ``.rl`` file and the properties, with their SHA-256 digests in the
  ``skinet.attachments`` metadata record;
* a ``skinet`` metadata record: versions, the system's name, the budget and the
  policy (``unknown`` where the writer could not know them), what triggered it.

Streams are opened and closed by the caller.  Cost: O(messages) to write and
read; reading keeps the wire messages (the view channels are skipped).
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import IO, Any

from pydantic import BaseModel, ValidationError

from skinet.errors import SkinetError
from skinet.files import program
from skinet.wire.log import Entry
from skinet.wire.mcap_log import MAGIC, McapLogWriter, _entry
from skinet.wire.messages import ModelBundle

MODEL = "model.json"
ATTACHMENTS = "skinet.attachments"
META = "skinet"
VIEW_PREFIX = "/skinet/"  # the Foxglove channels; wire keys have no leading slash


def sha256(data: bytes) -> str:
    return "sha256:" + hashlib.sha256(data).hexdigest()


def model_files(model: ModelBundle) -> dict[str, bytes]:
    """The attachments of a model: ``model.json``, the ``.rl`` files and the properties."""
    files = {MODEL: json.dumps(model.model_dump(mode="json"), sort_keys=True, indent=1).encode()}
    for name, text, _node in model.skillsets:
        files[f"skillsets/{name}"] = text.encode()
    files[f"properties/{model.properties_name}"] = model.properties.encode()
    return files


class BundleWriter:
    """Writes one bundle to ``stream``: messages first, then :meth:`finish` with the model."""

    def __init__(self, stream: IO[bytes]):
        self._log = McapLogWriter(stream)
        self._writer = self._log._writer
        self._view: dict[str, int] = {}
        self._sequence = 0

    def wire(self, key: str, message: BaseModel, t: float) -> None:
        """A wire message received on ``key`` at ``t`` (seconds)."""
        self._log.write(key, message, t)

    def view(self, topic: str, schema_name: str, schema: Mapping[str, Any], message: Mapping[str, Any],
             t_ns: int) -> None:
        """A message of a Foxglove channel (:mod:`skinet.wire.foxglove`) at ``t_ns``."""
        channel = self._view.get(topic)
        if channel is None:
            sid = self._writer.register_schema(schema_name, "jsonschema", json.dumps(schema).encode())
            channel = self._view[topic] = self._writer.register_channel(topic, "json", sid)
        self._sequence += 1
        self._writer.add_message(channel, log_time=t_ns, publish_time=t_ns, sequence=self._sequence,
                                 data=json.dumps(message, separators=(",", ":")).encode())

    def finish(self, model: ModelBundle, metadata: Mapping[str, str], t_ns: int) -> None:
        files = model_files(model)
        for name, data in files.items():
            self._writer.add_attachment(create_time=t_ns, log_time=t_ns, name=name,
                                        media_type="application/json" if name.endswith(".json") else "text/plain",
                                        data=data)
        self._writer.add_metadata(ATTACHMENTS, {name: sha256(data) for name, data in files.items()})
        self._writer.add_metadata(META, dict(metadata))
        self._log.finish()


@dataclass
class Bundle:
    """What a bundle holds, checked."""

    entries: list[Entry]  # wire messages, in log-time order
    model: ModelBundle
    metadata: dict[str, str] = field(default_factory=dict)


def read_bundle(stream: IO[bytes], source: str) -> Bundle:
    """Read and check a bundle; raises one-line :class:`SkinetError` for a file that is not MCAP, is truncated,
    has no model, or whose attachments do not match their recorded digests."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    head = stream.read(len(MAGIC))
    if not head.startswith(MAGIC):
        raise SkinetError(f"{source}: not an MCAP file (it does not start with the MCAP magic bytes)")
    stream.seek(0)
    entries: list[Entry] = []
    try:
        reader = make_reader(stream)
        summary = reader.get_summary()
        if summary is None:
            raise SkinetError(f"{source}: truncated bundle (no summary: the writer did not finish it)")
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for mschema, channel, message in reader.iter_messages(log_time_order=True):
            if channel.topic.startswith(VIEW_PREFIX):
                continue
            problem = _entry(mschema, channel, message, entries)
            if problem:
                raise SkinetError(f"{source}: message {message.sequence} on {channel.topic}: {problem}")
    except (McapError, EOFError, ValueError, KeyError, struct.error) as exc:
        raise SkinetError(f"{source}: truncated or damaged bundle: {str(exc) or type(exc).__name__}") from None
    digests = metadata.get(ATTACHMENTS)
    if digests is None or MODEL not in attachments:
        raise SkinetError(f"{source}: not a SkiNet bundle (no model attachment and digests; a monitor log? "
                          f"{program.skinet()} replay plays those without --verify)")
    for name in sorted(set(digests) | set(attachments)):
        found = sha256(attachments[name]) if name in attachments else "missing"
        if found != digests.get(name, "not recorded"):
            raise SkinetError(f"{source}: attachment {name} was altered: recorded digest "
                              f"{digests.get(name, 'none')}, found {found}")
    try:
        model = ModelBundle.model_validate_json(attachments[MODEL])
    except ValidationError as exc:
        raise SkinetError(f"{source}: attachment {MODEL} is no model bundle: {exc.errors()[0]['msg']}") from None
    return Bundle(entries, model, metadata.get(META, {}))
