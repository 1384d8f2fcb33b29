"""Canonical events of a system as a subscriber on Zenoh sees them (service and DDS tests)."""

from __future__ import annotations

import threading
from collections.abc import Callable

import zenoh

from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import CanonicalEvent


class Events:
    """Canonical events of a system, in arrival order."""

    def __init__(self, session: zenoh.Session, system: str):
        self.items: list[CanonicalEvent] = []
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(keys.events(system, "*"), self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.items.append(decode(sample.payload.to_bytes(), CanonicalEvent))
            self._cond.notify_all()

    def wait(self, predicate: Callable[[list[CanonicalEvent]], bool], timeout: float = 5.0) -> list[CanonicalEvent]:
        with self._cond:
            assert self._cond.wait_for(lambda: predicate(self.items), timeout), self.items
            return list(self.items)

    def of(self, skillset: str) -> list[CanonicalEvent]:
        with self._cond:
            return [e for e in self.items if e.skillset == skillset]
