"""Violation onsets: the steps at which a property became violated (docs/semantics.md §7), without I/O.

A step's :class:`~skinet.wire.messages.Verdicts` says which properties are violated now;
the next step no longer does when the violation ended, so a view that joins later never
saw it.  :class:`ViolationOnsets` follows the violated set from step to step and returns
the properties that were not violated at the step before (the monitor's first step counts
every violation then as an onset).  The monitor lists each onset in its run's
:class:`~skinet.wire.messages.Divergences` list (kind ``violation``, its step, event and
property), which it publishes and answers on ``get`` to joining views: bounded as that
list is (the last :data:`~skinet.wire.messages.MAX_DIVERGENCES` entries, older ones
counted), see docs/operator.md.  Cost: O(P) per step for P properties.
"""

from __future__ import annotations

from collections.abc import Iterable


class ViolationOnsets:
    """The violated properties of the last step (not thread-safe: the monitor holds its lock)."""

    def __init__(self) -> None:
        self.violated: frozenset[str] = frozenset()
        self.total = 0  # onsets so far

    def step(self, violated: Iterable[str]) -> list[str]:
        """The properties violated at this step and not at the one before, in the order given."""
        now = list(dict.fromkeys(violated))
        onsets = [p for p in now if p not in self.violated]
        self.violated = frozenset(now)
        self.total += len(onsets)
        return onsets


def onset_reason(prop: str) -> str:
    """The listed entry's reason for an onset of ``prop``."""
    return f"{prop} is violated from this step"


def onset_property(reason: str) -> str | None:
    """The property of an onset's reason (:func:`onset_reason`); None for another text."""
    suffix = " is violated from this step"
    return reason[:-len(suffix)] if reason.endswith(suffix) and len(reason) > len(suffix) else None
