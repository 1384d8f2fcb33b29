"""Which predictor instance gets the next query: least outstanding, then least recent (docs/semantics.md §7).

The monitor learns the instances from their liveliness tokens and counts its own
queries in flight on each.  :meth:`Pool.pick` prefers instances not suspected of
being frozen, then the fewest outstanding queries, then the one used least
recently; instances start in random order, so monitors that share a pool do not
all begin with the same instance.  A suspicion (silence while a query was in
flight) lasts ``suspicion`` seconds, about the liveliness lease after which a
frozen instance's token disappears anyway, or until the instance answers or
its token is declared again.  Cost: O(instances) per pick.
"""

from __future__ import annotations

import random
import time
from dataclasses import dataclass


@dataclass
class _Instance:
    outstanding: int = 0
    last_used: float = 0.0  # order of use; random below 0 until first used
    suspect_until: float = 0.0


class Pool:
    """Live predictor instances and this monitor's load on each (not thread-safe: the caller locks)."""

    def __init__(self, suspicion: float = 10.0):
        self.suspicion = suspicion
        self._instances: dict[str, _Instance] = {}
        self._uses = 0

    def __len__(self) -> int:
        return len(self._instances)

    def names(self) -> list[str]:
        return sorted(self._instances)

    def add(self, name: str) -> None:
        """A token appeared (also again after a freeze: the suspicion ends)."""
        inst = self._instances.setdefault(name, _Instance(last_used=-random.random()))
        inst.suspect_until = 0.0

    def remove(self, name: str) -> None:
        self._instances.pop(name, None)

    def pick(self, exclude: set[str] = frozenset()) -> str | None:  # type: ignore[assignment]
        """The instance for the next query, or None when every instance is excluded."""
        now = time.monotonic()
        best = min(((inst.suspect_until > now, inst.outstanding, inst.last_used, name)
                    for name, inst in self._instances.items() if name not in exclude), default=None)
        return None if best is None else best[3]

    def sent(self, name: str) -> None:
        inst = self._instances.setdefault(name, _Instance())
        self._uses += 1
        inst.outstanding += 1
        inst.last_used = self._uses

    def returned(self, name: str) -> None:
        """A query sent to ``name`` is over (it may have been removed meanwhile)."""
        if name in self._instances:
            self._instances[name].outstanding = max(0, self._instances[name].outstanding - 1)

    def answered(self, name: str) -> None:
        if name in self._instances:
            self._instances[name].suspect_until = 0.0

    def suspect(self, name: str) -> None:
        if name in self._instances:
            self._instances[name].suspect_until = time.monotonic() + self.suspicion
