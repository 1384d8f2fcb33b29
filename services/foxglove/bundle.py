"""Incident bundles written from what a Zenoh view receives (docs/foxglove.md): ``skinet record --bundle``, ``--incidents``.

:class:`BundleSink` takes the messages ``skinet record`` receives: it writes each
wire message as it came, feeds a :class:`~services.dashboard.board.Board` and a
:class:`~services.foxglove.translate.Translator` to write the same run on the
Foxglove channels, and at the end attaches the model bundle (a bundle without a
model is refused: it could not be verified).  Cost: O(1) per message (the
translation's), memory O(the board's bounded history).
"""

from __future__ import annotations

import time
from typing import BinaryIO

from pydantic import BaseModel

from services.dashboard.board import Board
from services.foxglove.translate import Translator
from skinet import __version__
from skinet.errors import SkinetError
from skinet.wire import foxglove as fx
from skinet.wire.bundle import BundleWriter
from skinet.wire.messages import ModelBundle

SPECS = {spec.topic: spec for spec in fx.channels()}


class BundleSink:
    """A ``skinet record`` sink writing an incident bundle of system ``system``."""

    def __init__(self, out: BinaryIO, system: str, trigger: str = "skinet record --bundle (the whole run)"):
        self.out, self.system = out, system
        self.writer = BundleWriter(out)
        self.board = Board(system)
        self.translator = Translator(system)
        self.model: ModelBundle | None = None
        self.trigger = trigger

    def write(self, key: str, message: BaseModel, t: float) -> None:
        if isinstance(message, ModelBundle):
            self.model = self.model or message
            return  # an attachment, written at the end
        self.writer.wire(key, message, t)
        for topic, body, t_ns in self.translator.feed(self.board.feed(message, t)):
            spec = SPECS[topic]
            self.writer.view(topic, spec.schema_name, spec.schema, body, t_ns)

    def close(self) -> None:
        try:
            if self.model is None:
                raise SkinetError(f"no model bundle of system '{self.system}' came from its monitor: a bundle "
                                  "without the model cannot be verified (is the monitor reachable?)")
            meta = {"skinet": __version__, "system": self.system, "digest": self.model.digest,
                    "budget": "unknown", "policy": "unknown", "trigger": self.trigger}
            self.writer.finish(self.model, meta, int(time.time() * 1e9))
        finally:
            self.out.close()
