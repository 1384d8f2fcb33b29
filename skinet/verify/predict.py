"""mu1 = Sat(AF not phi) per property, with steps and witnesses (docs/semantics.md §6.2).

A marking in mu1 inevitably violates phi.  Each property is predicted with
*fair* AF (:mod:`skinet.verify.fair`: only paths on which running skills end
count; the default) or *literal* AF (the paper's, every path; ``rank`` is then
the bound on steps), as the system's prediction options say.  The witness
follows, from the marking, successors of strictly smaller rank down to a
violating marking.  On a truncated exploration the answer is three-valued:
*dangerous* (proven in mu1), *safe* (a path inside the explored part avoids the
violation forever) or *undecided*.

Cost: exploration (:mod:`skinet.verify.explore`), then per property one
counting fixpoint (literal) or one SCC decomposition and backward search per
bound (fair), all linear in the explored markings and edges.  Where the
product box reaches :data:`skinet.verify.symbolic.SYMBOLIC_FROM` markings and
CUDD is installed, fair AF is computed with decision diagrams instead
(:mod:`skinet.verify.symbolic`: no edge list, exact at every stored marking).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from skinet.lang.expr import Not
from skinet.system.prediction import PredictionOptions
from skinet.system.model import System
from skinet.verify.algorithm1 import PredictionVerdict
from skinet.verify.ctl import UNREACHED, Kripke, Result, af, check
from skinet.verify import symbolic
from skinet.verify.component import ComponentGraph, Expired
from skinet.verify.explore import (DEFAULT_MEMORY_LIMIT, Deadline, StateSpace, component_graphs, explore,
                                   local_indices)
from skinet.verify.compositional import compositional_oracle, one_step
from skinet.verify.fair import distance_to, fair_af, skill_fairness
from skinet.verify.forced import forced_mask
from skinet.verify.scc import warm_up_for


@dataclass
class PropertyRisk:
    """mu1 of one property over the explored markings.

    ``af`` names the AF the operator view uses (``mu1``); the other one and the
    forced set are filled only when a full report was asked for.
    """

    name: str
    violating: np.ndarray  # phi fails here
    af: str  # "fair" or "literal"
    fair: Result | None = None  # fair AF not phi, rank = fewest steps
    literal: Result | None = None  # literal AF not phi, rank = bound on steps
    forced: np.ndarray | None = None  # forced(phi) (docs/semantics.md §6.3)

    @property
    def mu1(self) -> Result:
        chosen = self.fair if self.af == "fair" else self.literal
        assert chosen is not None
        return chosen

    def counts(self, stored: np.ndarray) -> dict[str, int]:
        """Marking counts; implicit and forced ones exclude the violating markings."""
        violating = int(np.count_nonzero(self.violating & stored))
        dangerous = int(np.count_nonzero(self.mu1.lower))
        undecided = int(np.count_nonzero(self.mu1.upper & ~self.mu1.lower))
        out = {
            "violating": violating,
            "dangerous": dangerous,
            "undecided": undecided,
            "safe": int(np.count_nonzero(stored)) - dangerous - undecided,
        }
        for mode, result in (("fair", self.fair), ("literal", self.literal)):
            if result is not None:
                out[f"implicit_{mode}"] = int(np.count_nonzero(result.lower)) - violating
                out[f"undecided_{mode}"] = int(np.count_nonzero(result.upper & ~result.lower))
        if self.forced is not None:
            out["forced"] = int(np.count_nonzero(self.forced & stored)) - violating
        return out


@dataclass
class SymbolicFair:
    """Fair AF by decision diagrams: the product and each property's violation, for steps and witnesses."""

    product: symbolic.SymbolicProduct
    violating: dict[str, symbolic.Function]
    deadline: Deadline

    def dangerous(self, prop: str, marking: Mapping[str, int]) -> PredictionVerdict:
        """A marking of fair mu1: the fewest steps to a violation and one such path, when found in time."""
        graphs = self.product.graphs
        local = local_indices(graphs, marking)
        path = None if local is None else self.product.shortest_path(local, self.violating[prop], self.deadline)
        if path is None:
            return PredictionVerdict("dangerous")
        return PredictionVerdict("dangerous", len(path),
                                 tuple(f"{graphs[i].name}:{graphs[i].labels[(a, b)]}" for i, a, b in path))


@dataclass
class Forecast:
    """The predictor's answer: the explored space and mu1 for every property."""

    space: StateSpace
    kripke: Kripke
    risks: dict[str, PropertyRisk]
    # Verdicts for markings the exploration left undecided (docs/semantics.md §6.4), when given.
    fallback: Callable[[str, Mapping[str, int]], PredictionVerdict] | None = None
    symbolic_fair: SymbolicFair | None = None  # fair AF was computed with decision diagrams

    def verdict(self, prop: str, marking: Mapping[str, int]) -> PredictionVerdict:
        """Algorithm 1's view of one marking (the :class:`Prediction` protocol)."""
        code = self.space.code(marking)
        if code is None or not self.kripke.stored[code]:
            return self.fallback(prop, marking) if self.fallback else PredictionVerdict("undecided")
        risk = self.risks[prop]
        if risk.mu1.lower[code]:
            if risk.af == "fair" and self.symbolic_fair is not None:
                return self.symbolic_fair.dangerous(prop, marking)
            rank = int(self.ranks(prop)[code])
            if rank == UNREACHED:  # fair AF: no violation reachable inside the explored part
                return PredictionVerdict("dangerous")
            return PredictionVerdict("dangerous", rank, self.witness(prop, code))
        if not risk.mu1.upper[code]:
            return PredictionVerdict("safe")
        return self.fallback(prop, marking) if self.fallback else PredictionVerdict("undecided")

    def ranks(self, prop: str) -> np.ndarray:
        """Steps to a violation of ``prop`` per marking: the bound (literal AF) or the fewest (fair AF).

        Fair ranks are computed on first use: most answers never need them.
        """
        mu1 = self.risks[prop].mu1
        if mu1.rank is None:
            mu1.rank = distance_to(self.kripke, self.risks[prop].violating)
        return mu1.rank

    def witness(self, prop: str, code: int) -> tuple[str, ...]:
        """Transitions along one path from ``code`` to a violation of ``prop``."""
        rank = self.ranks(prop)
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
            "af": {name: r.af for name, r in self.risks.items()},
        }


def forecast(
    system: System,
    marking: Mapping[str, int] | None = None,
    *,
    budget: float | None = None,
    max_depth: int | None = None,
    event_seeds: bool = True,
    progress: Callable[[int, int, float], None] | None = None,
    options: PredictionOptions | None = None,
    full: bool = False,
    memory_limit: int | None = DEFAULT_MEMORY_LIMIT,
    compositional: bool = True,
) -> Forecast:
    """Explore from ``marking`` and compute mu1 for every property of ``system``.

    ``options`` (default: the system's) choose fair or literal AF per property;
    ``full`` also computes the other AF and the forced set, for reports.
    ``budget`` (seconds) bounds the whole answer, fixpoints included;
    ``memory_limit`` (bytes, whole process) bounds what is stored (docs/semantics.md §6.1).
    With ``compositional``, markings the exploration leaves undecided are
    decided by :mod:`skinet.verify.compositional` where it can (docs/semantics.md §6.4).
    """
    options = options or system.prediction
    marking = dict(marking or system.initial_marking())
    fair = full or any(options.of(p.name).af == "fair" for p in system.properties)
    answer = Deadline.after(budget)
    # Half the budget is kept for the compositional verdicts of what stays undecided.
    deadline = Deadline.after(None if budget is None else 0.5 * budget)
    try:  # explored once: the scipy warm-up, the exploration and the BDD share them
        graphs: list[ComponentGraph] | None = component_graphs(system, marking, event_seeds, deadline)
    except Expired:
        graphs = None  # explore() stores the live marking alone and says why
    if fair or compositional:
        # scipy imported when the graphs may need it (a one-time 0.15-0.3 s, not counted in the budget).
        imported = warm_up_for(graphs)
        for d in (answer, deadline):
            if d.at is not None:
                d.at += imported
    by_bdd = (fair and graphs is not None and math.prod(g.size for g in graphs) >= symbolic.SYMBOLIC_FROM
              and symbolic.available())
    space = explore(system, marking, max_depth=max_depth, event_seeds=event_seeds, progress=progress,
                    memory_limit=memory_limit, properties=len(system.properties) * (2 if full else 1),
                    edges=fair and not by_bdd, deadline=deadline, graphs=graphs)
    kripke = Kripke(space)
    fairness: list[np.ndarray] | None = None
    # Past the deadline the BDD would decide nothing: the explicit fair AF then says
    # "undecided" at once, without the dd import or an edge list.
    product = symbolic.SymbolicProduct(space.components) if by_bdd and not deadline.expired() else None
    symbolic_fairness = [] if product is None else product.skill_fairness(system)
    phi = {} if product is None else {p.name: product.formula(p.expr) for p in system.properties}
    risks = {}
    for p in system.properties:
        opts = options.of(p.name)
        violated = check(kripke, Not(p.expr))
        risk = PropertyRisk(p.name, violated.lower, opts.af)
        if full or opts.af == "literal":
            risk.literal = af(kripke, violated)
        if (full or opts.af == "fair") and product is not None:
            risk.fair = _symbolic_fair_af(kripke, product, phi[p.name], symbolic_fairness)
        elif full or opts.af == "fair":
            fairness = skill_fairness(kripke, system) if fairness is None else fairness
            risk.fair = fair_af(kripke, violated, fairness)
        if full:
            risk.forced = forced_mask(system, space.components, space.local, p, opts.events_uncontrollable)
        risks[p.name] = risk
    oracle = compositional_oracle(system)
    oracle.remember(space.components)
    props = {p.name: p for p in system.properties}

    def fallback(prop: str, marking: Mapping[str, int]) -> PredictionVerdict:
        return oracle.verdict(props[prop], marking, options.of(prop).af, answer)

    if compositional and kripke.truncated_by is not None:
        # Algorithm 1 asks about the one-step successors: decide them now, within the budget.
        for after in one_step(system, marking):
            for name in props:
                fallback(name, after)

    sym = None if product is None else SymbolicFair(product, {name: ~f for name, f in phi.items()}, answer)
    return Forecast(space, kripke, risks, fallback if compositional else None, sym)


def _symbolic_fair_af(
    kripke: Kripke, product: symbolic.SymbolicProduct, phi: symbolic.Function,
    fairness: list[symbolic.Function],
) -> Result:
    """Fair AF not phi over the stored markings, exact, or undecided everywhere past the deadline."""
    eg = product.fair_eg(phi, fairness, kripke.deadline)
    if eg is None:
        kripke.cut = True
        return Result(np.zeros(kripke.space.size, dtype=bool), kripke.stored.copy())
    sat = np.logical_not(product.mask(eg, kripke.space))
    sat &= kripke.stored
    return Result(sat, sat)
