"""Canonical events in the order their messages arrived, across skillsets and kinds of bridge (docs/semantics.md §1, §7).

The monitor follows the interleaving the robot went through only if the bridge
emits events in the order their messages came.  A derivation may have to wait
before it can name what a message did: a manager's status that overtook its
response (:class:`~services.bridge_ros2.feed.Feed`), a bound skill's terminal goal
whose mode needs its result (:class:`~services.bridge_ros2.bound.BoundFeed`).  Such
a message takes an *open slot*: its events, when they come, go in its place, and
every event placed after it waits behind it.  One :class:`Order` shared by the
manager feed and the bound feed of one bridge process orders both kinds together.

Not thread-safe (the bridge's worker thread owns it).  Cost: O(1) per placement,
O(events) per drain.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from skinet.wire.messages import CanonicalEvent


@dataclass
class Slot:
    """A place in the order; open while the message it stands for waits to be derived."""

    events: list[CanonicalEvent] = field(default_factory=list)
    open: bool = True


class Order:
    """Events waiting for their turn."""

    def __init__(self) -> None:
        self._slots: deque[Slot] = deque()

    def place(self, events: list[CanonicalEvent]) -> None:
        """Events derived at once: after everything placed before."""
        if events:
            self._slots.append(Slot(list(events), open=False))

    def open(self) -> Slot:
        """A place for events to come (a message that waits): what is placed later waits behind it."""
        slot = Slot()
        self._slots.append(slot)
        return slot

    @staticmethod
    def close(slot: Slot, events: list[CanonicalEvent] = ()) -> None:  # type: ignore[assignment]
        """``slot``'s message was derived: its events take its place."""
        slot.events += events
        slot.open = False

    def due(self) -> bool:
        """Whether events are ready to be taken (:meth:`drain`)."""
        return bool(self._slots) and not self._slots[0].open

    def drain(self) -> list[CanonicalEvent]:
        """The events whose turn has come: everything up to the first open slot."""
        out: list[CanonicalEvent] = []
        while self._slots and not self._slots[0].open:
            out += self._slots.popleft().events
        return out


__all__ = ["Order", "Slot"]
