"""Following the live robot on its nets (docs/semantics.md §1 monitor, §7 model divergence).

Canonical events name a model-level transition of one skillset and may carry
the status observed after it.  The live marking advances by that transition
(with its invariant cascade); when the observation disagrees with every
possible result, or no transition explains it, the change is reported as a
*divergence* and the observed marking is adopted.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from skinet.errors import SourceError
from skinet.net.semantics import enabled, stable_successors
from skinet.system.model import Marking, System, marking_from_json


@dataclass(frozen=True)
class Outcome:
    """What one event did to the live marking."""

    skillset: str
    transition: str | None
    changed: bool
    divergence: str | None = None  # why the model could not explain the event


class LiveSystem:
    """The live combined marking of a system, advanced event by event."""

    def __init__(self, system: System, marking: Mapping[str, int] | None = None):
        self.system = system
        self.marking: Marking = dict(marking or system.initial_marking())

    def apply(self, skillset: str, transition: str | None, observed: Mapping | None = None) -> Outcome:
        """Advance ``skillset`` by ``transition`` (logical name) and/or to ``observed``.

        ``observed`` is ``{"resources": {...}, "running": [...]}`` for that
        skillset, as in :func:`skinet.system.model.marking_from_json`.
        """
        try:
            comp = self.system.component(skillset)
        except KeyError:
            names = ", ".join(c.name for c in self.system.components)
            return Outcome(skillset, transition, False, f"unknown skillset '{skillset}' (skillsets: {names})")
        current = self.marking[skillset]
        target: int | None = None
        if observed is not None:
            try:
                target = marking_from_json(self.system, {skillset: observed})[skillset]
            except SourceError as exc:
                return Outcome(skillset, transition, False, f"unreadable status: {exc.diagnostics[0].message}")
        if transition is not None and all(t.name != transition for t in comp.net.transitions):
            return self._diverge(skillset, transition, target, f"unknown transition '{transition}' of '{skillset}'")
        firable = enabled(comp.net, current)
        # Without a transition name, any firable transition may explain the status.
        chosen = [t for t in firable if transition is None or t.name == transition]
        results: set[int] = set()
        for t in chosen:
            results |= stable_successors(comp.net, current, t)
        if target is None:
            if transition is None:
                return Outcome(skillset, None, False)
            if not results:
                return Outcome(skillset, transition, False, f"'{transition}' is not enabled in the live marking")
            # Several results only when invariants race; any one is a faithful guess.
            self.marking[skillset] = min(results)
            return Outcome(skillset, transition, True)
        if target == current and transition is None:
            return Outcome(skillset, None, False)
        if target in results:
            self.marking[skillset] = target
            return Outcome(skillset, transition, target != current)
        if transition is not None and not chosen:
            reason = f"'{transition}' is not enabled in the live marking"
        else:
            reason = f"no transition explains the observed status of '{skillset}'"
        return self._diverge(skillset, transition, target, reason)

    def _diverge(self, skillset: str, transition: str | None, target: int | None, reason: str) -> Outcome:
        changed = target is not None and target != self.marking[skillset]
        if target is not None:
            self.marking[skillset] = target
            reason += "; observed marking adopted"
        return Outcome(skillset, transition, changed, reason)
