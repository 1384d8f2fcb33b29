"""CTL model checking on an explored state space, three-valued (SPEC §6).

Every formula evaluates to a pair of boolean arrays over the product box,
``(lower, upper)``: ``lower`` is where it provably holds, ``upper`` where it
may hold; they agree on a complete exploration.  Frontier markings (stored,
not expanded) have unknown successors: ``EX``/``AX`` are false there for
``lower`` and true for ``upper``, which makes both fixpoints sound because
every operator is monotone.  Deadlocks are sink states: they loop on
themselves, so ``AF f`` holds at a deadlock only if ``f`` does.

Fixpoints use the linear-time counting algorithms of Clarke, Emerson and
Sistla (1986) on predecessors generated from the product structure; ``AF`` and
``AU`` also return each marking's rank, the bound on steps to ``f``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skinet.lang.expr import And, Const, Expr, Implies, Not, Or
from skinet.props.evaluate import evaluate
from skinet.props.formula import PlaceAtom, Temporal, Until
from skinet.verify.explore import StateSpace, expand_codes

UNREACHED = np.iinfo(np.int32).max


@dataclass
class Kripke:
    """Successor structure of a :class:`StateSpace`, precomputed for fixpoints."""

    space: StateSpace

    def __post_init__(self) -> None:
        s = self.space
        self.stored = s.stored()
        self.expanded = s.expanded()
        self.frontier = self.stored & ~self.expanded
        self.rev = [g.csr(reverse=True) for g in s.components]
        outdeg = np.zeros(s.box, dtype=np.int32)
        loop = np.zeros(s.box, dtype=bool)
        for i, g in enumerate(s.components):
            outdeg += s.local(g.csr()[2], i).astype(np.int32)
            loop |= s.local(g.loop, i)
        self.deadlock = self.expanded & (outdeg == 0) & ~loop
        # Deadlocks are sinks: their only successor is themselves.
        self.loop = loop | self.deadlock
        self.outdeg = outdeg + self.loop

    def predecessors(self, codes: np.ndarray) -> np.ndarray:
        """Expanded non-loop predecessors of ``codes`` (one entry per edge)."""
        s = self.space
        preds = expand_codes(codes, s.strides, s.shape, self.rev)
        return preds[self.expanded[preds]]

    def ex(self, z: np.ndarray, frontier_value: bool) -> np.ndarray:
        """EX z: some successor satisfies z."""
        out = np.zeros_like(z)
        out[self.predecessors(np.flatnonzero(z & self.stored))] = True
        out |= self.loop & z
        out &= self.expanded
        if frontier_value:
            out |= self.frontier
        return out

    def ax(self, z: np.ndarray, frontier_value: bool) -> np.ndarray:
        """AX z: every successor satisfies z."""
        out = self.expanded & ~self.ex(~z & self.stored, False)
        if frontier_value:
            out |= self.frontier
        return out

    def eu(self, f: np.ndarray, g: np.ndarray, frontier_value: bool) -> np.ndarray:
        """E[f U g] by backward search from g through f."""
        sat = g & self.stored
        ok = f & self.stored & (self.expanded | frontier_value)
        if frontier_value:
            sat = sat | (ok & self.frontier)
        layer = np.flatnonzero(sat)
        while layer.size:
            p = self.predecessors(layer)
            p = p[ok[p] & ~sat[p]]
            p = np.unique(p)
            sat[p] = True
            layer = p
        return sat

    def au(self, f: np.ndarray, g: np.ndarray, frontier_value: bool) -> tuple[np.ndarray, np.ndarray]:
        """A[f U g] and each satisfying marking's rank (max steps to reach g)."""
        rank = np.full(self.space.box, UNREACHED, dtype=np.int32)
        sat = g & self.stored
        rank[sat] = 0
        ok = f & self.expanded
        remaining = self.outdeg.copy()  # a loop is never discharged: it keeps f alive forever
        if frontier_value:
            sat |= self.frontier & f
        layer = np.flatnonzero(sat)
        level = 0
        while layer.size:
            level += 1
            p = self.predecessors(layer)
            p = p[ok[p] & ~sat[p]]
            np.subtract.at(remaining, p, 1)
            p = np.unique(p)
            p = p[remaining[p] == 0]
            sat[p] = True
            rank[p] = level
            layer = p
        return sat, rank

    def eg(self, f: np.ndarray, frontier_value: bool) -> np.ndarray:
        """EG f: some path stays in f forever (greatest fixpoint)."""
        sat = f & self.stored
        if not frontier_value:
            sat &= self.expanded
        # count successors inside sat
        inside = np.zeros(self.space.box, dtype=np.int32)
        codes = np.flatnonzero(sat)
        p = self.predecessors(codes)
        np.add.at(inside, p, 1)
        inside += (self.loop & sat)
        removable = sat & self.expanded & (inside == 0)
        layer = np.flatnonzero(removable)
        while layer.size:
            sat[layer] = False
            p = self.predecessors(layer)
            p = p[sat[p]]
            np.subtract.at(inside, p, 1)
            p = np.unique(p)
            layer = p[inside[p] == 0]
        return sat


@dataclass
class Result:
    """A formula's three-valued satisfaction and, for AF/AU, the ranks."""

    lower: np.ndarray
    upper: np.ndarray
    rank: np.ndarray | None = None


def check(kripke: Kripke, formula: Expr) -> Result:
    """Evaluate ``formula`` (state formulas, EX AX EF AF EG AG EU AU) on ``kripke``."""
    s = kripke.space
    if isinstance(formula, (PlaceAtom, Const)) or not _temporal(formula):
        v = evaluate(formula, lambda a: _atom(s, a))
        v = np.broadcast_to(np.asarray(v, dtype=bool), (s.box,)) & kripke.stored
        return Result(v.copy(), v.copy())
    if isinstance(formula, Not):
        r = check(kripke, formula.arg)
        return Result(~r.upper & kripke.stored, ~r.lower & kripke.stored)
    if isinstance(formula, (And, Or, Implies)):
        a, b = check(kripke, formula.left), check(kripke, formula.right)
        if isinstance(formula, And):
            return Result(a.lower & b.lower, a.upper & b.upper)
        if isinstance(formula, Or):
            return Result(a.lower | b.lower, a.upper | b.upper)
        st = kripke.stored
        return Result((~a.upper & st) | b.lower, (~a.lower & st) | b.upper)
    if isinstance(formula, Until):
        a, b = check(kripke, formula.left), check(kripke, formula.right)
        if formula.quantifier == "E":
            return Result(kripke.eu(a.lower, b.lower, False), kripke.eu(a.upper, b.upper, True))
        lo, rank = kripke.au(a.lower, b.lower, False)
        hi, _ = kripke.au(a.upper, b.upper, True)
        return Result(lo, hi, rank)
    if isinstance(formula, Temporal):
        a = check(kripke, formula.arg)
        everywhere = kripke.stored
        op = formula.op
        if op == "EX":
            return Result(kripke.ex(a.lower, False), kripke.ex(a.upper, True))
        if op == "AX":
            return Result(kripke.ax(a.lower, False), kripke.ax(a.upper, True))
        if op == "EF":
            return Result(kripke.eu(everywhere, a.lower, False), kripke.eu(everywhere, a.upper, True))
        if op == "AF":
            lo, rank = kripke.au(everywhere, a.lower, False)
            hi, _ = kripke.au(everywhere, a.upper, True)
            return Result(lo, hi, rank)
        if op == "EG":
            return Result(kripke.eg(a.lower, False), kripke.eg(a.upper, True))
        if op == "AG":  # AG f = not EF not f
            lo_ef = kripke.eu(everywhere, ~a.upper & everywhere, False)
            hi_ef = kripke.eu(everywhere, ~a.lower & everywhere, True)
            return Result(~hi_ef & everywhere, ~lo_ef & everywhere)
    raise TypeError(f"not a CTL formula: {formula!r}")


def _temporal(expr: Expr) -> bool:
    if isinstance(expr, (Temporal, Until)):
        return True
    if isinstance(expr, Not):
        return _temporal(expr.arg)
    if isinstance(expr, (And, Or, Implies)):
        return _temporal(expr.left) or _temporal(expr.right)
    return False


def _atom(space: StateSpace, atom: PlaceAtom) -> np.ndarray:
    for i, g in enumerate(space.components):
        if g.name == atom.skillset:
            bit = 1 << g.net.place_index(atom.place)
            return space.local(np.array([bool(m & bit) for m in g.states]), i)
    raise KeyError(atom.skillset)
