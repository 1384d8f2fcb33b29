"""Requests to skillset managers over Zenoh, as an operator GUI sends them (docs/semantics.md §8, corpus README).

:class:`Requests` declares one publisher per request topic of every manager of a
system (skill requests and interrupts, event and status requests; keys of
:class:`~skinet.ros.keys.KeyStyle`) and puts the CDR of :mod:`skinet.ros.requests`
on them, with ``CongestionControl.BLOCK`` (a request must not be dropped, ZENOH.md)
and, with ``rmw_zenoh`` keys, the 33-byte attachment of one writer.  The
simulator's driver and the pilot's :class:`~services.pilot.act.ManagerActuator` share it.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING

import zenoh

from services.common.zenoh_config import undeclare
from skinet.ros.keys import KeyStyle, ManagerTopic, manager_topics
from skinet.ros.requests import Writer
from skinet.system.model import Component

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

REQUEST_KINDS = ("skill_request", "skill_interrupt", "event_request", "status_request")


class Requests:
    """Publishers on the request topics of ``nodes`` (component, its type store); thread-safe."""

    def __init__(self, session: zenoh.Session, nodes: Iterable[tuple[Component, Typestore]],
                 style: KeyStyle = KeyStyle(), gid: bytes | None = None):
        self.style = style
        self._writer = Writer(gid or os.urandom(16))
        self._lock = threading.Lock()
        self._publishers: dict[tuple[str, str], zenoh.Publisher] = {}
        self.keys: dict[tuple[str, str], str] = {}  # (skillset, node-relative topic) -> key
        for component, store in nodes:
            for t in manager_topics(component.skillset):
                if t.kind in REQUEST_KINDS:
                    key = style.key(component.manager, t, store)
                    self.keys[(component.name, t.topic)] = key
                    self._publishers[(component.name, t.topic)] = session.declare_publisher(
                        key, congestion_control=zenoh.CongestionControl.BLOCK)

    def put(self, skillset: str, topic: ManagerTopic, payload: bytes) -> str:
        """Publish ``payload`` on ``skillset``'s ``topic``; returns the key (``KeyError`` if unknown)."""
        with self._lock:
            pub = self._publishers[(skillset, topic.topic)]
            attachment = self._writer.attachment(time.time_ns()) if self.style.rmw_zenoh else None
            pub.put(payload, attachment=attachment)
        return self.keys[(skillset, topic.topic)]

    def close(self) -> None:
        with self._lock:
            publishers, self._publishers = list(self._publishers.values()), {}
        undeclare(*publishers)


__all__ = ["REQUEST_KINDS", "Requests"]
