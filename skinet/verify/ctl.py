"""CTL model checking on an explored state space, three-valued (SPEC §6).

Every formula evaluates to a pair of boolean arrays over the index space,
``(lower, upper)``: ``lower`` is where it provably holds, ``upper`` where it
may hold; they agree on a complete exploration.  Frontier markings (stored,
not expanded) have unknown successors: ``EX``/``AX`` are false there for
``lower`` and true for ``upper``, which makes both fixpoints sound because
every operator is monotone.  Deadlocks are sink states: they loop on
themselves, so ``AF f`` holds at a deadlock only if ``f`` does.

Fixpoints use the linear-time counting algorithms of Clarke, Emerson and
Sistla (1986) on predecessors generated from the product structure; ``AF`` and
``AU`` also return each marking's rank, the bound on steps to ``f``.  Cost:
linear in the stored markings and edges; memory: a few bytes per index (one
per boolean array, one for ``outdeg``, one or two for ranks) plus chunks.  The
space's deadline is checked per chunk, so the budget bounds the fixpoints too.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from skinet.lang.expr import And, Const, Expr, Implies, Not, Or
from skinet.props.evaluate import evaluate
from skinet.props.formula import PlaceAtom, Temporal, Until, is_temporal
from skinet.verify.explore import CHUNK, StateSpace, expand_codes, expand_edges, unique_codes


UNREACHED = np.iinfo(np.int32).max  # distance or rank of a marking from which the target is not known reachable


@dataclass
class Kripke:
    """Successor structure of a :class:`StateSpace`, precomputed for fixpoints.

    Arrays over the space's index space: ``stored``, ``expanded``,
    ``frontier``, ``deadlock`` and ``loop`` (booleans; read-only broadcast
    views where constant) and ``outdeg`` (successors, self-loop included; one
    byte for the usual sizes).  Every fixpoint checks the space's deadline per
    chunk; when it expires, the fixpoint returns a sound approximation in the
    direction asked (under for ``lower``, over for ``upper``) and
    ``truncated_by`` becomes ``"budget"``.
    """

    space: StateSpace

    def __post_init__(self) -> None:
        s = self.space
        self.deadline = s.deadline
        self.cut = False  # a fixpoint was interrupted by the deadline
        self.stored = s.stored()
        self.expanded = s.expanded()
        self.frontier = s.frontier()
        self.exact = s.complete  # no frontier: lower and upper coincide
        self.rev = [g.csr(reverse=True) for g in s.components]
        bound = 1 + sum(int(g.csr()[2].max(initial=0)) for g in s.components)
        self.degree_dtype = next(t for t in (np.int8, np.int16, np.int32) if bound <= np.iinfo(t).max)
        outdeg, loop = self._local_degrees()
        dead = (outdeg == 0) & ~loop & self.expanded
        del outdeg, loop
        self.deadlock = dead if dead.any() else np.broadcast_to(np.False_, (s.size,))

    def _local_degrees(self) -> tuple[np.ndarray, np.ndarray]:
        """Out-degree without self-loops and self-loop flag, from the components' graphs."""
        s = self.space
        dtype = self.degree_dtype
        if s.codes is None:
            outdeg = np.zeros(s.shape, dtype=dtype)
            loop = np.zeros(s.shape, dtype=bool)
            for i, g in enumerate(s.components):  # broadcast in place: no box-sized temporaries
                view = [1] * len(s.shape)
                view[i] = s.shape[i]
                outdeg += g.csr()[2].astype(dtype).reshape(view)
                loop |= g.loop.reshape(view)
            return outdeg.reshape(-1), loop.reshape(-1)
        outdeg = np.zeros(s.size, dtype=dtype)
        loop = np.zeros(s.size, dtype=bool)
        for lo in range(0, s.size, CHUNK):
            codes = s.codes[lo:lo + CHUNK]
            for i, g in enumerate(s.components):
                digit = (codes // s.strides[i]) % s.shape[i]
                outdeg[lo:lo + CHUNK] += g.csr()[2].astype(dtype)[digit]
                loop[lo:lo + CHUNK] |= g.loop[digit]
        return outdeg, loop

    @cached_property
    def loop(self) -> np.ndarray:
        """A step back to itself (deadlocks included: they are sinks)."""
        return self._local_degrees()[1] | self.deadlock

    @cached_property
    def outdeg(self) -> np.ndarray:
        """Successors, self-loop included."""
        return self.fresh_outdeg()

    def fresh_outdeg(self) -> np.ndarray:
        """A new :attr:`outdeg` array (the counting fixpoints consume one each; not kept)."""
        outdeg, loop = self._local_degrees()
        loop |= self.deadlock
        outdeg += loop
        return outdeg

    @property
    def truncated_by(self) -> str | None:
        return self.space.truncated_by or ("budget" if self.cut else None)

    def _expired(self) -> bool:
        if self.deadline.expired():
            self.cut = True
            return True
        return False

    def _initial(self, g: np.ndarray, extra: np.ndarray | None) -> Iterator[np.ndarray]:
        """Indices of ``(g & stored) | extra``, block by block (no copy of the whole set)."""
        step = CHUNK * 32
        for lo in range(0, self.space.size, step):
            block = g[lo:lo + step] & self.stored[lo:lo + step]
            if extra is not None:
                block |= extra[lo:lo + step]
            idx = np.flatnonzero(block)
            if idx.size:
                yield idx + lo

    def _all(self) -> np.ndarray:
        return np.array(self.stored, dtype=bool)

    def predecessor_chunks(self, idx: np.ndarray) -> Iterator[np.ndarray]:
        """Expanded non-loop predecessors of ``idx`` (one entry per edge), chunk by chunk.

        Stops early once the deadline has expired.
        """
        s = self.space
        for lo in range(0, idx.size, CHUNK):
            if self._expired():
                return  # the caller sees the deadline expired and falls back
            preds = expand_codes(s.code_of(idx[lo:lo + CHUNK]), s.strides, s.shape, self.rev)
            preds = s.index(preds)
            if s.codes is not None or s.stored_mask is not None:
                preds = preds[preds >= 0]
            yield preds[self.expanded[preds]]

    def predecessors(self, idx: np.ndarray) -> np.ndarray:
        """Expanded non-loop predecessors of ``idx`` (one entry per edge)."""
        return np.concatenate([np.empty(0, dtype=np.int64), *self.predecessor_chunks(idx)])

    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """``(sources, targets)`` indices of every non-loop edge leaving an expanded marking (computed once).

        Up to about 80 bytes per edge with the copies its users make; the
        exploration plans for it (``explore(..., edges=True)``).
        """
        cache = self.__dict__.get("_edges")
        if cache is None:
            s = self.space
            fwd = [g.csr() for g in s.components]
            idx = np.flatnonzero(self.expanded)
            src, dst = [np.empty(0, dtype=np.int64)], [np.empty(0, dtype=np.int64)]
            for lo in range(0, idx.size, CHUNK):
                a, b = expand_edges(s.code_of(idx[lo:lo + CHUNK]), s.strides, s.shape, fwd)
                src.append(s.index(a))
                dst.append(s.index(b))
            cache = self.__dict__["_edges"] = (np.concatenate(src), np.concatenate(dst))
        return cache

    def _ex(self, z: np.ndarray, frontier_value: bool, over: bool) -> np.ndarray:
        out = self.loop & z
        for mask_idx in _nonzero_chunks(z & self.stored):
            for p in self.predecessor_chunks(mask_idx):
                out[p] = True
            if self._expired():
                if over:
                    return self._all()
                break
        out &= self.expanded
        if frontier_value:
            out |= self.frontier
        return out

    def ex(self, z: np.ndarray, frontier_value: bool) -> np.ndarray:
        """EX z: some successor satisfies z."""
        return self._ex(z, frontier_value, frontier_value)

    def ax(self, z: np.ndarray, frontier_value: bool) -> np.ndarray:
        """AX z: every successor satisfies z."""
        out = self.expanded & ~self._ex(~z & self.stored, False, not frontier_value)
        if frontier_value:
            out |= self.frontier
        return out

    def eu(self, f: np.ndarray, g: np.ndarray, frontier_value: bool) -> np.ndarray:
        """E[f U g] by backward search from g through f."""
        sat = g & self.stored
        ok = f & self.stored & (self.expanded | frontier_value)
        if frontier_value:
            sat |= ok & self.frontier
        layers = self._initial(g, ok & self.frontier if frontier_value else None)
        while True:
            found = []
            for layer in layers:
                for p in self.predecessor_chunks(layer):
                    p = unique_codes(p[ok[p] & ~sat[p]])
                    sat[p] = True
                    found.append(p)
                if self._expired():
                    return self._all() if frontier_value else sat
            if not found:
                return sat
            layers = [np.concatenate(found)]

    def au(
        self, f: np.ndarray, g: np.ndarray, frontier_value: bool, ranks: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """A[f U g] and, with ``ranks``, each satisfying marking's rank (max steps to reach g).

        Counting algorithm: a marking of ``f`` joins once every successor has;
        a loop is never discharged, so it keeps ``f`` alive forever.  Ranks
        start as one byte and widen when the levels need it; unreached markings
        hold the dtype's maximum.
        """
        remaining = self.fresh_outdeg()
        rank = np.full(self.space.size, np.iinfo(np.uint8).max, dtype=np.uint8) if ranks else None
        sat = g & self.stored
        if rank is not None:
            rank[sat] = 0
        ok = self.expanded if f is self.stored else f & self.expanded
        if frontier_value:
            sat |= self.frontier & f
        layers = self._initial(g, self.frontier & f if frontier_value else None)
        level = 0
        while True:
            level += 1
            if rank is not None and level >= np.iinfo(rank.dtype).max:
                wider = np.uint16 if rank.dtype == np.uint8 else np.uint32
                rank = np.where(rank == np.iinfo(rank.dtype).max, np.iinfo(wider).max, rank).astype(wider)
            found = []
            for layer in layers:
                for p in self.predecessor_chunks(layer):
                    p = p[ok[p] & ~sat[p]]
                    np.subtract.at(remaining, p, 1)
                    p = unique_codes(p[remaining[p] == 0])
                    sat[p] = True
                    if rank is not None:
                        rank[p] = level
                    found.append(p)
                if self._expired():
                    return (self._all() if frontier_value else sat), rank
            if not found:
                return sat, rank
            layers = [np.concatenate(found)]

    def eg(self, f: np.ndarray, frontier_value: bool) -> np.ndarray:
        """EG f: some path stays in f forever (greatest fixpoint)."""
        sat = f & self.stored
        if not frontier_value:
            sat &= self.expanded
        inside = (self.loop & sat).astype(self.degree_dtype)  # successors inside sat
        for idx in _nonzero_chunks(sat):
            for p in self.predecessor_chunks(idx):
                np.add.at(inside, p, 1)
            if self._expired():
                return sat if frontier_value else np.zeros(self.space.size, dtype=bool)
        layers = _nonzero_chunks(sat & self.expanded & (inside == 0))
        while True:
            found = []
            for layer in layers:
                sat[layer] = False
                found_here = []
                for p in self.predecessor_chunks(layer):
                    p = p[sat[p]]
                    np.subtract.at(inside, p, 1)
                    p = unique_codes(p[inside[p] == 0])
                    sat[p] = False
                    found_here.append(p)
                found.extend(found_here)
                if self._expired():
                    return sat if frontier_value else np.zeros(self.space.size, dtype=bool)
            if not found:
                return sat
            layers = [np.concatenate(found)]


def _nonzero_chunks(mask: np.ndarray) -> Iterator[np.ndarray]:
    """Indices where ``mask`` holds, chunk by chunk (no index array over the whole mask).

    Pass a mask nobody changes while the chunks are consumed.
    """
    step = CHUNK * 32
    for lo in range(0, mask.size, step):
        idx = np.flatnonzero(mask[lo:lo + step])
        if idx.size:
            yield idx + lo


@dataclass
class Result:
    """A formula's three-valued satisfaction and, for AF/AU, the ranks."""

    lower: np.ndarray
    upper: np.ndarray
    rank: np.ndarray | None = None


def check(kripke: Kripke, formula: Expr) -> Result:
    """Evaluate ``formula`` (state formulas, EX AX EF AF EG AG EU AU) on ``kripke``.

    On a complete exploration ``lower`` and ``upper`` are one array unless the
    deadline cut a fixpoint.
    """
    s = kripke.space
    st = kripke.stored
    if isinstance(formula, (PlaceAtom, Const)) or not is_temporal(formula):
        v = evaluate(formula, lambda a: place_values(s, a))
        v = np.broadcast_to(np.asarray(v, dtype=bool), (s.size,)) & st
        return Result(v, v)
    if isinstance(formula, Not):
        r = check(kripke, formula.arg)
        lo = ~r.upper & st
        return Result(lo, lo if r.upper is r.lower else ~r.lower & st)
    if isinstance(formula, (And, Or, Implies)):
        a, b = check(kripke, formula.left), check(kripke, formula.right)
        same = a.lower is a.upper and b.lower is b.upper
        if isinstance(formula, And):
            lo = a.lower & b.lower
            return Result(lo, lo if same else a.upper & b.upper)
        if isinstance(formula, Or):
            lo = a.lower | b.lower
            return Result(lo, lo if same else a.upper | b.upper)
        lo = (~a.upper & st) | b.lower
        return Result(lo, lo if same else (~a.lower & st) | b.upper)
    if isinstance(formula, Until):
        a, b = check(kripke, formula.left), check(kripke, formula.right)
        if formula.quantifier == "E":
            return _pair(kripke, a, b, lambda f, g, up: (kripke.eu(f, g, up), None))
        return _pair(kripke, a, b, lambda f, g, up: kripke.au(f, g, up, ranks=not up))
    if isinstance(formula, Temporal):
        a = check(kripke, formula.arg)
        op = formula.op
        if op == "EX":
            return _pair(kripke, a, a, lambda _, z, up: (kripke.ex(z, up), None))
        if op == "AX":
            return _pair(kripke, a, a, lambda _, z, up: (kripke.ax(z, up), None))
        if op == "EF":
            return _pair(kripke, a, a, lambda _, z, up: (kripke.eu(st, z, up), None))
        if op == "AF":
            return _pair(kripke, a, a, lambda _, z, up: kripke.au(st, z, up, ranks=not up))
        if op == "EG":
            return _pair(kripke, a, a, lambda _, z, up: (kripke.eg(z, up), None))
        if op == "AG":  # AG f = not EF not f
            r = check(kripke, Temporal("EF", Not(formula.arg)))
            lo = ~r.upper & st
            return Result(lo, lo if r.upper is r.lower else ~r.lower & st)
    raise TypeError(f"not a CTL formula: {formula!r}")


def _pair(kripke: Kripke, a: Result, b: Result, op) -> Result:
    """``op(f, g, upper)`` on the lower then the upper operands (once when exact and not cut)."""
    lo, rank = op(a.lower, b.lower, False)
    if kripke.exact and a.lower is a.upper and b.lower is b.upper and not kripke.cut:
        return Result(lo, lo, rank)
    hi, _ = op(a.upper, b.upper, True)
    return Result(lo, hi, rank)


def place_values(space: StateSpace, atom: PlaceAtom) -> np.ndarray:
    """Where ``atom``'s place is marked, over the whole space."""
    for i, g in enumerate(space.components):
        if g.name == atom.skillset:
            bit = 1 << g.net.place_index(atom.place)
            return space.local(np.array([bool(m & bit) for m in g.states]), i)
    raise KeyError(atom.skillset)
