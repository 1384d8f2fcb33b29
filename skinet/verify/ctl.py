"""CTL model checking on an explored state space, three-valued (docs/semantics.md §6).

Every formula evaluates to a pair of boolean arrays over the index space,
``(lower, upper)``: ``lower`` is where it provably holds, ``upper`` where it
may hold; they agree on a complete exploration.  Frontier markings (stored,
not expanded) have unknown successors: ``EX``/``AX`` are false there for
``lower`` and true for ``upper``, which makes both fixpoints sound because
every operator is monotone.  Deadlocks are sink states: they loop on
themselves, so ``AF f`` holds at a deadlock only if ``f`` does.

Fixpoints use the linear-time counting algorithms of Clarke, Emerson and
Sistla (1986) on predecessors generated from the product structure; ``AF`` and
``AU`` also return each marking's rank, the bound on steps to ``f``.  ``AF g``
(mu1, docs/semantics.md §6.2) is computed as ``not EG not g`` where that side is cheaper: on
the box, "has a successor in Z" is one vectorised pass over slices of the box
per component edge, with no index arithmetic at all.  Cost:
linear in the stored markings and edges; memory: a few bytes per index (one
per boolean array, one for ``outdeg``, one or two for ranks) plus chunks.  One
deadline (the space's) bounds the whole evaluation: every fixpoint and every
pass over the markings checks it per chunk, and past it each remaining operator
costs O(1) (docs/how-it-works.md, "One deadline bounds the whole evaluation").
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
# Atoms of a state formula evaluated whatever the deadline (one pass over the markings each);
# past the deadline, a state formula with more is undecided: the work stays bounded.
GRACE_ATOMS = 8


class _Late(Exception):
    """The deadline passed while a state formula was being evaluated."""


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
        self.deadlock = self._deadlocks()

    def _deadlocks(self) -> np.ndarray:
        """Expanded markings with no step at all (a read-only view when there is none).

        On the box, a deadlock is a product of the components' stuck states, so
        there is one unless some component is never stuck: no box-sized pass then.
        """
        s = self.space
        none = np.broadcast_to(np.False_, (s.size,))
        if s.codes is None:
            stuck = [(g.csr()[2] == 0) & ~g.loop for g in s.components]
            if not all(x.any() for x in stuck):
                return none
            dead = np.ones(s.shape, dtype=bool)
            for i, x in enumerate(stuck):
                view = [1] * len(s.shape)
                view[i] = s.shape[i]
                dead &= x.reshape(view)
            dead = dead.reshape(-1) & self.expanded
        else:
            degrees = self._local_degrees(timed=False)  # once per structure, whatever the deadline
            assert degrees is not None
            outdeg, loop = degrees
            dead = (outdeg == 0) & ~loop & self.expanded
        return dead if dead.any() else none

    def _local_degrees(self, timed: bool = True) -> tuple[np.ndarray, np.ndarray] | None:
        """Out-degree without self-loops and self-loop flag, from the components' graphs.

        ``None`` when ``timed`` and the deadline expires during the pass (checked
        per component on the box, per chunk elsewhere): partial degrees would
        discharge markings too early in the counting fixpoints.
        """
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
                if timed and self._expired():
                    return None
            return outdeg.reshape(-1), loop.reshape(-1)
        outdeg = np.zeros(s.size, dtype=dtype)
        loop = np.zeros(s.size, dtype=bool)
        for lo in range(0, s.size, CHUNK):
            codes = s.codes[lo:lo + CHUNK]
            for i, g in enumerate(s.components):
                digit = (codes // s.strides[i]) % s.shape[i]
                outdeg[lo:lo + CHUNK] += g.csr()[2].astype(dtype)[digit]
                loop[lo:lo + CHUNK] |= g.loop[digit]
            if timed and self._expired():
                return None
        return outdeg, loop

    @cached_property
    def loop(self) -> np.ndarray:
        """A step back to itself (deadlocks included: they are sinks); computed once, whatever the deadline."""
        degrees = self._local_degrees(timed=False)
        assert degrees is not None
        return degrees[1] | self.deadlock

    def timed_loop(self) -> np.ndarray | None:
        """:attr:`loop`, or ``None`` when the deadline expires before it is known (it is kept once known)."""
        if "loop" not in self.__dict__:
            degrees = self._local_degrees()
            if degrees is None:
                return None
            self.__dict__["loop"] = degrees[1] | self.deadlock
        return self.loop

    @cached_property
    def outdeg(self) -> np.ndarray:
        """Successors, self-loop included."""
        degrees = self._local_degrees(timed=False)
        assert degrees is not None
        return self._with_loops(*degrees)

    def fresh_outdeg(self) -> np.ndarray | None:
        """A new :attr:`outdeg` array (the counting fixpoints consume one each; not kept).

        ``None`` when the deadline expires during the pass.
        """
        degrees = self._local_degrees()
        return None if degrees is None else self._with_loops(*degrees)

    def _with_loops(self, outdeg: np.ndarray, loop: np.ndarray) -> np.ndarray:
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
        """Indices of ``(g & stored) | extra``, block by block (no copy of the whole set).

        Stops early once the deadline has expired (the caller checks it after the loop).
        """
        step = CHUNK * 32
        for lo in range(0, self.space.size, step):
            if self._expired():
                return
            block = g[lo:lo + step] & self.stored[lo:lo + step]
            if extra is not None:
                block |= extra[lo:lo + step]
            idx = np.flatnonzero(block)
            if idx.size:
                yield idx + lo

    def _chunks(self, mask: np.ndarray) -> Iterator[np.ndarray]:
        """:func:`_nonzero_chunks`, stopping early once the deadline has expired (the caller checks it after)."""
        for idx in _nonzero_chunks(mask):
            if self._expired():
                return
            yield idx

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
        loop = self.timed_loop()
        out = np.zeros(self.space.size, dtype=bool) if loop is None else loop & z
        for mask_idx in self._chunks(z & self.stored):
            for p in self.predecessor_chunks(mask_idx):
                out[p] = True
        if self._expired():  # out is what was proven so far: an under-approximation
            if over:
                return self._all()
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
        if remaining is None:  # nothing proven (lower), everything possible (upper)
            unranked = np.full(self.space.size, np.iinfo(np.uint8).max, dtype=np.uint8) if ranks else None
            return (self._all() if frontier_value else np.zeros(self.space.size, dtype=bool)), unranked
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
        """EG f: some path stays in f forever (greatest fixpoint).

        One pass finds the markings of f with no successor in f (on the box, by
        slices of the box: one vectorised operation per component edge); then
        only the expanded predecessors of what was removed are checked again.
        Cost: one pass over the edges leaving f, plus, per removed marking, its
        predecessors' successors.  Cut by the deadline: f itself (upper) or
        nothing (lower).
        """
        return self._eg(f & self.stored, frontier_value)

    def _eg(self, sat: np.ndarray, frontier_value: bool) -> np.ndarray:
        """EG on ``sat`` = f & stored, an array the caller gives up (it becomes the result)."""
        if not frontier_value:
            sat &= self.expanded

        def cut() -> np.ndarray:
            return sat if frontier_value else np.zeros(self.space.size, dtype=bool)

        if self.space.codes is None:
            has = self._box_successor_in(sat)
            if has is None:
                return cut()
            drop = np.logical_not(has, out=has)
            drop &= sat
            drop &= self.expanded  # frontier markings keep their unknown successors
            sat ^= drop  # in place: peak memory is two booleans per box element
            removed = list(_nonzero_chunks(drop))
            del has, drop
        else:
            removed = []
            for block in self._chunks(sat & self.expanded):
                for lo in range(0, block.size, CHUNK):
                    idx = block[lo:lo + CHUNK]
                    removed.append(idx[~self.successor_in(sat, idx)])
                    if self._expired():
                        return cut()
            if self._expired():
                return cut()
            for idx in removed:
                sat[idx] = False
        while removed:
            candidates = [unique_codes(p[sat[p]]) for idx in removed for p in self.predecessor_chunks(idx)]
            if self._expired():
                return cut()
            todo = unique_codes(np.concatenate([np.empty(0, dtype=np.int64), *candidates]))
            removed = []
            for lo in range(0, todo.size, CHUNK):
                idx = todo[lo:lo + CHUNK]
                removed.append(idx[~self.successor_in(sat, idx)])
                if self._expired():
                    return cut()
            for idx in removed:
                sat[idx] = False
            removed = [idx for idx in removed if idx.size]
        return sat

    def af(self, g: np.ndarray, frontier_value: bool, ranks: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """AF g (every path meets g; the paper's mu1) as not EG not g, and with ``ranks`` the bound on steps.

        Same fixpoint as ``au(stored, g)``.  On the box, and wherever g holds
        at most of the stored markings, it is computed from the other side:
        markings that can avoid g forever are found by one pass over the edges
        (:meth:`eg`), and ranks cost only the markings of AF g outside g
        (:meth:`bound_ranks`).  Elsewhere the counting fixpoint from g is cheaper.
        """
        if self.space.codes is not None and 2 * np.count_nonzero(g & self.stored) < self.space.size:
            # Stored markings are looked up by binary search: start from the smaller side, g.
            return self.au(self.stored, g, frontier_value, ranks)
        avoid = np.logical_not(g)
        avoid &= self.stored
        sat = self._eg(avoid, not frontier_value)
        np.logical_not(sat, out=sat)
        sat &= self.stored
        if not ranks:
            return sat, None
        return sat, self.bound_ranks(g, sat)

    def bound_ranks(self, g: np.ndarray, sat: np.ndarray) -> np.ndarray:
        """Rank of each marking of ``sat`` = AF g: the bound on steps to g (0 on g).

        Kahn's algorithm on the markings of ``sat`` outside g, whose successors
        all lie in ``sat``: O(their markings and edges).  Unranked markings hold
        the dtype's maximum; past the deadline those of ``sat`` are dropped
        from it (an under-approximation, as the counting fixpoint gives).
        """
        s = self.space
        target = g & self.stored
        inner = np.flatnonzero(sat & ~target)
        m = inner.size
        local = np.zeros(m, dtype=np.int64)
        if m:
            fwd = [c.csr() for c in s.components]
            us, vs = [], []
            for lo in range(0, m, CHUNK):
                codes = s.code_of(inner[lo:lo + CHUNK])
                a, b = expand_edges(codes, s.strides, s.shape, fwd)
                v = np.searchsorted(inner, s.index(b))
                v[v == m] = 0
                inside = inner[v] == s.index(b)
                us.append(lo + np.searchsorted(codes, a[inside]))
                vs.append(v[inside])
                if self._expired():
                    break
            u, v = np.concatenate(us), np.concatenate(vs)
            remaining = np.bincount(u, minlength=m)
            order = np.argsort(v, kind="stable")
            preds = u[order]
            ptr = np.searchsorted(v[order], np.arange(m + 1))
            ready = np.flatnonzero(remaining == 0)
            level = 1
            while ready.size and not self._expired():
                local[ready] = level
                level += 1
                cnt = ptr[ready + 1] - ptr[ready]
                first = np.repeat(ptr[ready] - np.cumsum(cnt) + cnt, cnt)
                p = preds[first + np.arange(int(cnt.sum()))]
                remaining -= np.bincount(p, minlength=m)
                p = unique_codes(p)
                ready = p[remaining[p] == 0]
            sat[inner[local == 0]] = False
        top = int(local.max(initial=0))
        dtype = next(t for t in (np.uint8, np.uint16, np.uint32) if top < np.iinfo(t).max)
        rank = np.full(s.size, np.iinfo(dtype).max, dtype=dtype)
        rank[target] = 0
        rank[inner] = np.where(local > 0, local, np.iinfo(dtype).max)
        return rank

    def successor_in(self, z: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """For the sorted markings ``idx``: does some successor (self-loop included) lie in ``z``?"""
        s = self.space
        codes = s.code_of(idx)
        here = z[idx]
        out = self.deadlock[idx] & here
        fwd = []
        for i, c in enumerate(s.components):
            out |= c.loop[(codes // s.strides[i]) % s.shape[i]] & here
            fwd.append(c.csr())
        a, b = expand_edges(codes, s.strides, s.shape, fwd)
        j = s.index(b)
        hit = j >= 0
        hit[hit] = z[j[hit]]
        out[np.searchsorted(codes, a[hit])] = True
        return out

    def _box_successor_in(self, z: np.ndarray) -> np.ndarray | None:
        """Over the whole box: does some successor (self-loop included) lie in ``z``?  ``None`` past the deadline."""
        s = self.space
        zv = z.reshape(s.shape)
        out = np.zeros(s.shape, dtype=bool)
        for i, c in enumerate(s.components):
            axis = (slice(None),) * i
            for a, targets in enumerate(c.succ):
                here = out[axis + (slice(a, a + 1),)]  # a view, also for a single component
                for b in targets + [a] * bool(c.loop[a]):
                    np.logical_or(here, zv[axis + (slice(b, b + 1),)], out=here)
                if self._expired():
                    return None
        flat = out.reshape(-1)
        flat |= self.deadlock & z
        return flat


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


def constant(formula: Expr) -> bool | None:
    """The value ``formula`` takes at every marking of every system, when it needs no exploration.

    Every marking has a successor (deadlocks loop on themselves), so a
    temporal operator of a constant is that constant (``AG true``, ``EX true``,
    ``AF false``), and ``E[f U g]``/``A[f U g]`` take ``g``'s constant value.
    ``None`` when the value depends on the marking.  Cost: linear in the formula.
    """
    if isinstance(formula, Const):
        return formula.value
    if isinstance(formula, Not):
        c = constant(formula.arg)
        return None if c is None else not c
    if isinstance(formula, (And, Or, Implies)):
        left, right = constant(formula.left), constant(formula.right)
        if isinstance(formula, Implies):
            left = None if left is None else not left
        if isinstance(formula, And):
            return False if False in (left, right) else (True if left is right is True else None)
        return True if True in (left, right) else (False if left is right is False else None)
    if isinstance(formula, Temporal):
        return constant(formula.arg)
    if isinstance(formula, Until):
        return constant(formula.right)
    return None


def check(kripke: Kripke, formula: Expr) -> Result:
    """Evaluate ``formula`` (state formulas, EX AX EF AF EG AG EU AU) on ``kripke``.

    On a complete exploration ``lower`` and ``upper`` are one array unless the
    deadline cut a fixpoint.  A formula that needs no exploration
    (:func:`constant`) is answered exactly whatever was explored.  Once the
    deadline has passed, every operator not yet computed, and every operator
    whose operands return after it, is undecided at once (no fixpoint and no
    pass over the markings is started), and a state formula is evaluated only
    up to :data:`GRACE_ATOMS` atoms: the work past the budget is bounded by a
    constant, not by the formula (docs/commands.md, ``skinet ctl``).  Cost: one fixpoint
    per temporal operator, each linear in the stored markings and edges.
    """
    st = kripke.stored
    value = constant(formula)
    if value is not None:
        return _constant_result(kripke, formula, value)
    if isinstance(formula, (PlaceAtom, Const)) or not is_temporal(formula):
        return _state_formula(kripke, formula)
    if kripke._expired():
        return _undecided(kripke)
    if isinstance(formula, Not):
        a = check(kripke, formula.arg)
        return _undecided(kripke) if kripke._expired() else _negate(kripke, a)
    if isinstance(formula, (And, Or, Implies)):
        a, b = check(kripke, formula.left), check(kripke, formula.right)
        if kripke._expired():  # combining costs passes over the markings: none past the deadline
            return _undecided(kripke)
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
        if kripke._expired():
            return _undecided(kripke)
        if formula.quantifier == "E":
            return _pair(kripke, a, b, lambda f, g, up: (kripke.eu(f, g, up), None))
        return _pair(kripke, a, b, lambda f, g, up: kripke.au(f, g, up, ranks=not up))
    if isinstance(formula, Temporal):
        a = check(kripke, formula.arg)
        if kripke._expired():
            return _undecided(kripke)
        op = formula.op
        if op == "EX":
            return _pair(kripke, a, a, lambda _, z, up: (kripke.ex(z, up), None))
        if op == "AX":
            return _pair(kripke, a, a, lambda _, z, up: (kripke.ax(z, up), None))
        if op == "EF":
            return _ef(kripke, a)
        if op == "AF":
            return af(kripke, a)
        if op == "EG":
            return _pair(kripke, a, a, lambda _, z, up: (kripke.eg(z, up), None))
        if op == "AG":  # AG f = not EF not f, from f's result (checking f again would double the work per level)
            return _negate(kripke, _ef(kripke, _negate(kripke, a)))
    raise TypeError(f"not a CTL formula: {formula!r}")


def _state_formula(kripke: Kripke, formula: Expr) -> Result:
    """A formula without temporal operator, exact at every stored marking; undecided if late.

    Its first :data:`GRACE_ATOMS` atoms are evaluated whatever the deadline (a
    formula such as ``spot:Busy`` is still answered after a cut exploration);
    each further atom checks it.  Cost: one pass over the markings per atom
    (on the box, per local state) and per connective.
    """
    s = kripke.space
    box = s.codes is None  # on the box, atoms broadcast along their component's axis: one array at the end
    atoms = [0]

    def atom(a: PlaceAtom) -> np.ndarray:
        atoms[0] += 1
        if atoms[0] > GRACE_ATOMS and kripke._expired():
            raise _Late
        return place_values(s, a, flat=not box)

    try:
        v = evaluate(formula, atom)
    except _Late:
        return _undecided(kripke)
    v = np.broadcast_to(np.asarray(v, dtype=bool), s.shape if box else (s.size,)).reshape(-1) & kripke.stored
    return Result(v, v)


def _constant_result(kripke: Kripke, formula: Expr, value: bool) -> Result:
    """``value`` at every stored marking (read-only arrays), ranked 0 (AF/AU of true) where asked."""
    v = kripke.stored.view() if value else np.zeros(kripke.space.size, dtype=bool)
    v.flags.writeable = False
    rank = None
    if isinstance(formula, Until) and formula.quantifier == "A" or isinstance(formula, Temporal) and formula.op == "AF":
        rank = np.full(kripke.space.size, 0 if value else np.iinfo(np.uint8).max, dtype=np.uint8)
    return Result(v, v, rank)


def _undecided(kripke: Kripke) -> Result:
    """Nothing proven, everything stored possible (read-only arrays; no pass over the space)."""
    lower = np.zeros(kripke.space.size, dtype=bool)  # calloc: pages only touched if read
    upper = kripke.stored.view()
    lower.flags.writeable = upper.flags.writeable = False
    return Result(lower, upper)


def _negate(kripke: Kripke, r: Result) -> Result:
    st = kripke.stored
    lo = ~r.upper & st
    return Result(lo, lo if r.upper is r.lower else ~r.lower & st)


def _ef(kripke: Kripke, a: Result) -> Result:
    st = kripke.stored
    return _pair(kripke, a, a, lambda _, z, up: (kripke.eu(st, z, up), None))


def af(kripke: Kripke, g: Result, ranks: bool = True) -> Result:
    """AF g from g's own result (the lower run ranked when ``ranks``): mu1 from the violating set."""
    return _pair(kripke, g, g, lambda _, z, up: kripke.af(z, up, ranks=ranks and not up))


def _pair(kripke: Kripke, a: Result, b: Result, op) -> Result:
    """``op(f, g, upper)`` on the lower then the upper operands (once when exact and not cut).

    Past the deadline the upper run is not started: every stored marking stays
    possible, and ``lo`` (sound whatever cut it) is kept.
    """
    lo, rank = op(a.lower, b.lower, False)
    if kripke.exact and a.lower is a.upper and b.lower is b.upper and not kripke.cut:
        return Result(lo, lo, rank)
    if kripke._expired():
        return Result(lo, kripke.stored.view(), rank)
    hi, _ = op(a.upper, b.upper, True)
    return Result(lo, hi, rank)


def place_values(space: StateSpace, atom: PlaceAtom, flat: bool = True) -> np.ndarray:
    """Where ``atom``'s place is marked, over the whole space.

    With ``flat`` false, on the box: an array of the box's rank, long only
    along the atom's component, that broadcasts to the box's shape.
    """
    for i, g in enumerate(space.components):
        if g.name == atom.skillset:
            bit = 1 << g.net.place_index(atom.place)
            values = np.array([bool(m & bit) for m in g.states])
            if not flat and space.codes is None:
                view = [1] * len(space.shape)
                view[i] = space.shape[i]
                return values.reshape(view)
            return space.local(values, i)
    raise KeyError(atom.skillset)
