"""Fair AF over the whole product with binary decision diagrams (docs/semantics.md §6.2, §6.4).

The explicit fair AF (:mod:`skinet.verify.fair`) decomposes the explored
graph into strongly connected components and so holds its edge list, about
80 bytes per edge: on three corpus spots and three arms (122 023 936 stable
markings, 1.7e9 edges) that cannot fit a 1 GiB limit.  Here the
stable-marking graph is encoded instead, as a BDD (CUDD, through ``dd.cudd``):

* each component's local state (its :class:`ComponentGraph` index) in binary
  variables ``x``, primed copies ``y`` for successors, the bits of ``x`` and
  ``y`` interleaved and the components in the system's order;
* one relation ``T_i(x_i, y_i)`` per component, its steps and self-loops.
  The union is the asynchronous product of the components (docs/semantics.md §6.4), so a
  step of the product is one component's step, others standing still: the
  image is partitioned per component and no frame condition is ever built;
* a global deadlock (every component stuck) loops on itself, as in
  :class:`skinet.verify.ctl.Kripke`.

``fair EG f = nu Z. f and AND_k EX E[f U (Z and idle_k)]`` (Emerson and Lei
1987), one fairness constraint per skill; fair ``AF g = not fair-EG not g``.
The fixpoint is computed over the whole product of the component graphs:
every successor of a marking of that product lies in it, so the answer is
exact at every stored marking, whether or not the exploration is complete.
A shortest path to a violation (the fair *steps* and witness) comes from
forward onion rings from the marking, then one predecessor per ring.

Cost: BDD operations over the encoded sets, whose size follows the
structure, not the number of markings (a few thousand nodes for the corpus
products); the Emerson-Lei fixpoint nests one least fixpoint per skill inside
the greatest one.  Turning a set into a boolean array over the stored
markings costs one table lookup per component per marking.  A BDD operation
cannot be interrupted: the deadline is checked between fixpoint steps, and
past it the answer is ``None`` (undecided, never safe).

``dd.cudd`` comes with dd's x86_64 wheels; where it is missing,
:func:`available` is false and the explicit fair AF answers alone.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
from collections.abc import Iterable, Sequence
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from skinet.lang.expr import Expr
from skinet.props.evaluate import evaluate
from skinet.props.formula import PlaceAtom
from skinet.system.model import System
from skinet.verify.component import ComponentGraph
from skinet.verify.explore import CHUNK, Deadline, StateSpace
from skinet.verify.fair import idle_atoms

# From this many markings in the product box on, the BDD is faster than the explicit
# SCC decomposition (measured on corpus copies: 21 632 markings 33 ms against 10 ms,
# 212 992 markings 53 ms against 226 ms; 2 + 2 with seeds 0.15 s against 2.0 s).
SYMBOLIC_FROM = 1 << 16

Function = Any  # dd.cudd.Function


@cache
def available() -> bool:
    """Whether dd's CUDD extension is installed (dd's x86_64 wheels carry it).

    Looked up without importing dd (13 MiB): the exploration plans its memory
    before the decision diagrams are built.
    """
    spec = importlib.util.find_spec("dd")
    if spec is None or not spec.submodule_search_locations:
        return False
    suffixes = importlib.machinery.EXTENSION_SUFFIXES
    return any((Path(d) / f"cudd{s}").is_file() for d in spec.submodule_search_locations for s in suffixes)


def variables(graphs: Sequence[ComponentGraph]) -> tuple[list[list[str]], list[list[str]], list[str]]:
    """Per component, its bits ``x`` and primed bits ``y``; and the order to declare them (interleaved)."""
    x: list[list[str]] = []
    y: list[list[str]] = []
    order: list[str] = []
    for i, g in enumerate(graphs):
        bits = max(1, (g.size - 1).bit_length())
        x.append([f"x{i}_{b}" for b in range(bits)])
        y.append([f"y{i}_{b}" for b in range(bits)])
        for b in range(bits):
            order += [x[i][b], y[i][b]]
    return x, y, order


def cube(bdd: Any, names: Sequence[str], value: int) -> Function:
    """The binary variables ``names`` (least significant first) equal to ``value``."""
    f = bdd.true
    for b, n in enumerate(names):
        f &= bdd.var(n) if value >> b & 1 else ~bdd.var(n)
    return f


def cubes(bdd: Any, names: Sequence[str], values: Iterable[int]) -> Function:
    """The binary variables ``names`` equal to one of ``values``."""
    f = bdd.false
    for v in values:
        f |= cube(bdd, names, v)
    return f


class SymbolicProduct:
    """The asynchronous product of ``graphs`` as BDDs."""

    def __init__(self, graphs: Sequence[ComponentGraph]):
        import dd.cudd

        self.bdd = dd.cudd.BDD()
        self._and_exists = dd.cudd.and_exists
        self.graphs = list(graphs)
        self.x, self.y, order = variables(self.graphs)
        self.bdd.declare(*order)
        self.xs = [v for vs in self.x for v in vs]
        self._to_y = [dict(zip(self.x[i], self.y[i])) for i in range(len(self.graphs))]
        self._to_x = [dict(zip(self.y[i], self.x[i])) for i in range(len(self.graphs))]
        self.relation = [self._relation(i) for i in range(len(self.graphs))]
        dead = self.bdd.true
        for i, g in enumerate(self.graphs):
            dead &= self.states(i, [s for s in range(g.size) if not g.succ[s] and not g.loop[s]])
        self.deadlock = dead

    # ------------------------------------------------------------------ sets

    def _code(self, names: Sequence[str], value: int) -> Function:
        return cube(self.bdd, names, value)

    def states(self, i: int, indices: Iterable[int], primed: bool = False) -> Function:
        """Component ``i`` in one of the local states ``indices``, the others anywhere."""
        return cubes(self.bdd, self.y[i] if primed else self.x[i], indices)

    def _relation(self, i: int) -> Function:
        g = self.graphs[i]
        rel = self.bdd.false
        for a in range(g.size):
            targets = list(g.succ[a]) + ([a] if g.loop[a] else [])
            if targets:
                rel |= self._code(self.x[i], a) & self.states(i, targets, primed=True)
        return rel

    def marking(self, local: Sequence[int]) -> Function:
        """One product marking, by local state index per component."""
        f = self.bdd.true
        for i, s in enumerate(local):
            f &= self._code(self.x[i], s)
        return f

    def formula(self, expr: Expr) -> Function:
        """A state formula (docs/semantics.md §4) as the set of product markings where it holds."""
        def atom(a: PlaceAtom) -> Function:
            i = next(j for j, g in enumerate(self.graphs) if g.name == a.skillset)
            bit = self.graphs[i].net.place_index(a.place)
            return self.states(i, [s for s, m in enumerate(self.graphs[i].states) if m >> bit & 1])

        return evaluate(expr, atom, lambda v: self.bdd.true if v else self.bdd.false)

    def skill_fairness(self, system: System) -> list[Function]:
        """One fairness constraint per skill: its idle place is marked (docs/semantics.md §6.2)."""
        return [self.formula(a) for a in idle_atoms(self.graphs, system)]

    # ------------------------------------------------------------ fixpoints

    def _image(self, i: int, s: Function) -> Function:
        return self.bdd.let(self._to_x[i], self._and_exists(s, self.relation[i], set(self.x[i])))

    def _preimage(self, i: int, z: Function) -> Function:
        return self._and_exists(self.bdd.let(self._to_y[i], z), self.relation[i], set(self.y[i]))

    def ex(self, z: Function) -> Function:
        """Markings with a successor in ``z`` (a global deadlock is its own successor)."""
        pre = z & self.deadlock
        for i in range(len(self.graphs)):
            pre |= self._preimage(i, z)
        return pre

    def _eu(self, f: Function, g: Function, deadline: Deadline) -> Function | None:
        y = g
        while not deadline.expired():
            ny = y | (f & self.ex(y))
            if ny == y:
                return y
            y = ny
        return None

    def fair_eg(self, f: Function, fairness: Sequence[Function], deadline: Deadline) -> Function | None:
        """Fair EG ``f`` (Emerson-Lei); ``None`` when ``deadline`` passes first."""
        z = f
        while True:
            nz = f
            for fk in fairness or [self.bdd.true]:  # no constraint: plain EG, nu Z. f and EX Z
                eu = self._eu(f, z & fk, deadline)
                if eu is None:
                    return None
                nz &= self.ex(eu)
            if nz == z:
                return z
            z = nz

    # ------------------------------------------------------- explicit views

    def _layers(self, f: Function) -> list[np.ndarray]:
        """``f`` as lookup tables, one per component.

        Table ``i`` maps (node reached after components ``< i``, local state of
        component ``i``) to the node reached after component ``i``; the last
        table gives booleans.  Nodes are cofactors of ``f``, shared.
        """
        nodes: list[Function] = [f]
        tables: list[np.ndarray] = []
        for i, g in enumerate(self.graphs):
            found: dict[int, int] = {}  # by node: a Function's hash is its wrapper's, not its node's
            children: list[Function] = []
            table = np.empty((len(nodes), g.size), dtype=np.int64)
            for j, node in enumerate(nodes):
                for s in range(g.size):
                    child = self.bdd.let({v: bool(s >> b & 1) for b, v in enumerate(self.x[i])}, node)
                    k = found.setdefault(int(child), len(found))
                    if k == len(children):
                        children.append(child)
                    table[j, s] = k
            tables.append(table.astype(np.min_scalar_type(max(1, len(found) - 1))))
            nodes = children
        value = np.array([n == self.bdd.true for n in nodes], dtype=bool)
        tables[-1] = value[tables[-1]]
        return tables

    def mask(self, f: Function, space: StateSpace) -> np.ndarray:
        """``f`` at each marking of ``space``'s index space (the box, or the stored codes)."""
        tables = self._layers(f)
        if space.codes is None:
            node = tables[0][0]
            for t in tables[1:]:
                node = t[node.reshape(-1)[:, None], np.arange(t.shape[1])].reshape(*node.shape, t.shape[1])
            return node.reshape(-1)
        out = np.empty(space.size, dtype=bool)
        for lo in range(0, space.size, CHUNK):
            codes = space.codes[lo:lo + CHUNK]
            node = np.zeros(codes.size, dtype=np.int64)
            for i, t in enumerate(tables):
                node = t[node, (codes // space.strides[i]) % space.shape[i]]
            out[lo:lo + CHUNK] = node
        return out

    def _pick(self, f: Function) -> list[int]:
        """One marking of ``f`` (non-empty), as local state indices."""
        bits = self.bdd.pick(f, care_vars=set(self.xs))
        return [sum(1 << b for b, v in enumerate(names) if bits[v]) for names in self.x]

    def shortest_path(
        self, local: Sequence[int], target: Function, deadline: Deadline
    ) -> list[tuple[int, int, int]] | None:
        """Fewest steps from the marking ``local`` into ``target``: ``(component, from, to)`` per step.

        ``None`` when no path exists or the deadline passes first.
        """
        rings = [self.marking(local)]
        reached = rings[0]
        while (rings[-1] & target) == self.bdd.false:
            post = self.bdd.false
            for i in range(len(self.graphs)):
                post |= self._image(i, rings[-1])
            new = post & ~reached
            if new == self.bdd.false or deadline.expired():
                return None
            reached |= new
            rings.append(new)
        at = self._pick(rings[-1] & target)
        path: list[tuple[int, int, int]] = []
        for ring in reversed(rings[:-1]):
            here = self.marking(at)
            for i in range(len(self.graphs)):
                before = self._preimage(i, here) & ring
                if before != self.bdd.false:
                    prev = self._pick(before)
                    path.append((i, prev[i], at[i]))
                    at = prev
                    break
        path.reverse()
        return path

