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

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from skinet.lang.expr import And, Const, Expr, Implies, Not, Or
from skinet.props.evaluate import evaluate
from skinet.props.formula import PlaceAtom, Temporal, Until, is_temporal
from skinet.verify.explore import CHUNK, StateSpace, expand_codes, expand_edges, unique_codes

UNREACHED = np.iinfo(np.int32).max


@dataclass
class Kripke:
    """Successor structure of a :class:`StateSpace`, precomputed for fixpoints.

    Per box element: ``stored``, ``expanded``, ``frontier``, ``deadlock`` and
    ``loop`` (one byte each) and ``outdeg`` (two bytes for the usual sizes).
    """

    space: StateSpace

    def __post_init__(self) -> None:
        s = self.space
        self.stored = s.stored()
        self.expanded = s.expanded()
        self.frontier = self.stored & ~self.expanded
        self.rev = [g.csr(reverse=True) for g in s.components]
        bound = 1 + sum(int(g.csr()[2].max(initial=0)) for g in s.components)
        dtype = np.int16 if bound <= np.iinfo(np.int16).max else np.int32
        outdeg = np.zeros(s.shape, dtype=dtype)
        loop = np.zeros(s.shape, dtype=bool)
        for i, g in enumerate(s.components):  # broadcast in place: no box-sized temporaries
            view = [1] * len(s.shape)
            view[i] = s.shape[i]
            outdeg += g.csr()[2].astype(dtype).reshape(view)
            loop |= g.loop.reshape(view)
        outdeg, loop = outdeg.reshape(-1), loop.reshape(-1)
        self.deadlock = self.expanded & (outdeg == 0) & ~loop
        # Deadlocks are sinks: their only successor is themselves.
        loop |= self.deadlock
        outdeg += loop
        self.loop, self.outdeg = loop, outdeg

    def predecessor_chunks(self, codes: np.ndarray) -> Iterator[np.ndarray]:
        """Expanded non-loop predecessors of ``codes`` (one entry per edge), chunk by chunk."""
        s = self.space
        for lo in range(0, codes.size, CHUNK):
            preds = expand_codes(codes[lo:lo + CHUNK], s.strides, s.shape, self.rev)
            yield preds[self.expanded[preds]]

    def predecessors(self, codes: np.ndarray) -> np.ndarray:
        """Expanded non-loop predecessors of ``codes`` (one entry per edge)."""
        return np.concatenate([np.empty(0, dtype=np.int64), *self.predecessor_chunks(codes)])

    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """``(sources, targets)`` of every non-loop edge leaving an expanded marking (computed once)."""
        cache = self.__dict__.get("_edges")
        if cache is None:
            s = self.space
            fwd = [g.csr() for g in s.components]
            codes = np.flatnonzero(self.expanded)
            parts = [expand_edges(codes[lo:lo + CHUNK], s.strides, s.shape, fwd) for lo in range(0, codes.size, CHUNK)]
            cache = (np.concatenate([np.empty(0, dtype=np.int64), *(p[0] for p in parts)]),
                     np.concatenate([np.empty(0, dtype=np.int64), *(p[1] for p in parts)]))
            self.__dict__["_edges"] = cache
        return cache

    def ex(self, z: np.ndarray, frontier_value: bool) -> np.ndarray:
        """EX z: some successor satisfies z."""
        out = self.loop & z
        for p in self.predecessor_chunks(np.flatnonzero(z & self.stored)):
            out[p] = True
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
            sat |= ok & self.frontier
        layer = np.flatnonzero(sat)
        while layer.size:
            found = []
            for p in self.predecessor_chunks(layer):
                p = unique_codes(p[ok[p] & ~sat[p]])
                sat[p] = True
                found.append(p)
            layer = np.concatenate(found)
        return sat

    def au(
        self, f: np.ndarray, g: np.ndarray, frontier_value: bool, ranks: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """A[f U g] and, with ``ranks``, each satisfying marking's rank (max steps to reach g).

        Counting algorithm: a marking of ``f`` joins once every successor has;
        a loop is never discharged, so it keeps ``f`` alive forever.
        """
        rank = np.full(self.space.box, UNREACHED, dtype=np.int32) if ranks else None
        sat = g & self.stored
        if rank is not None:
            rank[sat] = 0
        ok = f & self.expanded
        remaining = self.outdeg.copy()
        if frontier_value:
            sat |= self.frontier & f
        layer = np.flatnonzero(sat)
        level = 0
        while layer.size:
            level += 1
            found = []
            for p in self.predecessor_chunks(layer):
                p = p[ok[p] & ~sat[p]]
                np.subtract.at(remaining, p, 1)
                p = unique_codes(p[remaining[p] == 0])
                sat[p] = True
                if rank is not None:
                    rank[p] = level
                found.append(p)
            layer = np.concatenate(found)
        return sat, rank

    def eg(self, f: np.ndarray, frontier_value: bool) -> np.ndarray:
        """EG f: some path stays in f forever (greatest fixpoint)."""
        sat = f & self.stored
        if not frontier_value:
            sat &= self.expanded
        inside = (self.loop & sat).astype(self.outdeg.dtype)  # successors inside sat
        for p in self.predecessor_chunks(np.flatnonzero(sat)):
            np.add.at(inside, p, 1)
        layer = np.flatnonzero(sat & self.expanded & (inside == 0))
        while layer.size:
            sat[layer] = False
            found = []
            for p in self.predecessor_chunks(layer):
                p = p[sat[p]]
                np.subtract.at(inside, p, 1)
                p = unique_codes(p[inside[p] == 0])
                sat[p] = False
                found.append(p)
            layer = np.concatenate(found)
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
    if isinstance(formula, (PlaceAtom, Const)) or not is_temporal(formula):
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
        hi, _ = kripke.au(a.upper, b.upper, True, ranks=False)
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
            hi, _ = kripke.au(everywhere, a.upper, True, ranks=False)
            return Result(lo, hi, rank)
        if op == "EG":
            return Result(kripke.eg(a.lower, False), kripke.eg(a.upper, True))
        if op == "AG":  # AG f = not EF not f
            lo_ef = kripke.eu(everywhere, ~a.upper & everywhere, False)
            hi_ef = kripke.eu(everywhere, ~a.lower & everywhere, True)
            return Result(~hi_ef & everywhere, ~lo_ef & everywhere)
    raise TypeError(f"not a CTL formula: {formula!r}")


def _atom(space: StateSpace, atom: PlaceAtom) -> np.ndarray:
    for i, g in enumerate(space.components):
        if g.name == atom.skillset:
            bit = 1 << g.net.place_index(atom.place)
            return space.local(np.array([bool(m & bit) for m in g.states]), i)
    raise KeyError(atom.skillset)
