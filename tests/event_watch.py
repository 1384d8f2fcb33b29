"""Messages of a system as a subscriber on Zenoh sees them: canonical events (service and DDS tests), any kind."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Generic, TypeVar

import zenoh
from pydantic import BaseModel

from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import CanonicalEvent

M = TypeVar("M", bound=BaseModel)


class Messages(Generic[M]):
    """The messages of type ``kind`` published on ``key_expr``, in arrival order."""

    def __init__(self, session: zenoh.Session, key_expr: str, kind: type[M]):
        self.items: list[M] = []
        self.kind = kind
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(key_expr, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.items.append(decode(sample.payload.to_bytes(), self.kind))
            self._cond.notify_all()

    def wait(self, predicate: Callable[[list[M]], bool], timeout: float = 5.0) -> list[M]:
        with self._cond:
            assert self._cond.wait_for(lambda: predicate(self.items), timeout), self.items
            return list(self.items)

    def seen(self, predicate: Callable[[list[M]], bool], timeout: float) -> bool:
        """Whether the messages satisfy ``predicate`` within ``timeout`` seconds."""
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self.items), timeout)


class Events(Messages[CanonicalEvent]):
    """Canonical events of a system, in arrival order."""

    def __init__(self, session: zenoh.Session, system: str):
        super().__init__(session, keys.events(system, "*"), CanonicalEvent)

    def of(self, skillset: str) -> list[CanonicalEvent]:
        with self._cond:
            return [e for e in self.items if e.skillset == skillset]
