"""mu1 = Sat(AF not phi) per property, with step bounds and witnesses (SPEC §6).

A marking in mu1 inevitably violates phi: on every path, within ``rank``
steps.  The witness follows, from the marking, successors of strictly smaller
rank down to a violating marking.  On a truncated exploration the answer is
three-valued: *dangerous* (proven in mu1), *safe* (a path inside the explored
part avoids the violation forever) or *undecided*.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from skinet.lang.expr import Not
from skinet.props.formula import Temporal
from skinet.system import System
from skinet.verify.algorithm1 import PredictionVerdict
from skinet.verify.ctl import Kripke, Result, check
from skinet.verify.explore import DEFAULT_MEMORY_LIMIT, Deadline, StateSpace, explore


@dataclass
class PropertyRisk:
    """mu1 of one property over the explored markings."""

    name: str
    violating: np.ndarray  # phi fails here
    mu1: Result  # AF not phi, with ranks

    def counts(self, stored: np.ndarray) -> dict[str, int]:
        dangerous = int(np.count_nonzero(self.mu1.lower))
        undecided = int(np.count_nonzero(self.mu1.upper & ~self.mu1.lower))
        return {
            "violating": int(np.count_nonzero(self.violating & stored)),
            "dangerous": dangerous,
            "undecided": undecided,
            "safe": int(np.count_nonzero(stored)) - dangerous - undecided,
        }


@dataclass
class Forecast:
    """The predictor's answer: the explored space and mu1 for every property."""

    space: StateSpace
    kripke: Kripke
    risks: dict[str, PropertyRisk]

    def verdict(self, prop: str, marking: Mapping[str, int]) -> PredictionVerdict:
        """Algorithm 1's view of one marking (the :class:`Prediction` protocol)."""
        code = self.space.code(marking)
        if code is None or not self.kripke.stored[code]:
            return PredictionVerdict("undecided")
        risk = self.risks[prop]
        if risk.mu1.lower[code]:
            return PredictionVerdict("dangerous", int(risk.mu1.rank[code]), self.witness(prop, code))
        if not risk.mu1.upper[code]:
            return PredictionVerdict("safe")
        return PredictionVerdict("undecided")

    def witness(self, prop: str, code: int) -> tuple[str, ...]:
        """Transitions along one path from ``code`` to a violation of ``prop``."""
        rank = self.risks[prop].mu1.rank
        path: list[str] = []
        while rank[code] > 0:
            nxt, label = min(self.space.successors(code), key=lambda s: rank[s[0]])
            path.append(label)
            code = nxt
        return tuple(path)

    def report(self) -> dict:
        """Summary as the ``state_space`` report of the paper plus per-property counts."""
        s = self.space
        stored = self.kripke.stored
        return {
            "elapsed": s.elapsed,
            "complete": s.complete and self.kripke.truncated_by is None,
            "timeout_reached": not s.complete,
            "truncated_by": self.kripke.truncated_by,
            "depth": s.expanded_depth,
            "markings": s.markings,
            "edges": s.edges,
            "deadlocks": int(np.count_nonzero(self.kripke.deadlock)),
            "frontier": int(np.count_nonzero(self.kripke.frontier)),
            "properties": {name: r.counts(stored) for name, r in self.risks.items()},
        }


def forecast(
    system: System,
    marking: Mapping[str, int] | None = None,
    *,
    budget: float | None = None,
    max_depth: int | None = None,
    event_seeds: bool = True,
    memory_limit: int | None = DEFAULT_MEMORY_LIMIT,
    progress: Callable[[int, int, float], None] | None = None,
) -> Forecast:
    """Explore from ``marking`` and compute mu1 for every property of ``system``.

    ``budget`` (seconds) bounds the whole answer, fixpoints and witnesses
    included; ``memory_limit`` (bytes, whole process) bounds the markings stored.
    """
    deadline = Deadline.after(budget)
    space = explore(system, marking, budget=budget, max_depth=max_depth, event_seeds=event_seeds,
                    memory_limit=memory_limit, properties=len(system.properties), progress=progress,
                    deadline=deadline)
    kripke = Kripke(space)
    risks = {}
    for p in system.properties:
        violating = ~check(kripke, p.expr).upper & kripke.stored
        risks[p.name] = PropertyRisk(p.name, violating, check(kripke, Temporal("AF", Not(p.expr))))
    return Forecast(space, kripke, risks)
