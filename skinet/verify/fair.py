"""Fair AF: inevitability over the paths on which every running skill ends (docs/semantics.md §6.2).

Literal ``AF g`` also counts the paths on which one skill runs forever while
another component cycles; in a product of components it almost never holds
outside ``g`` itself.  *Fair* AF only counts paths on which every skill is idle
infinitely often (one fairness constraint per skill: its idle place ``e_k``):

    fair AF g  =  not fair-EG (not g)

and fair-EG ``f`` holds where a path inside ``f`` reaches a *fair SCC* of the
graph restricted to ``f``: a strongly connected component with at least one
edge (a self-loop counts; a deadlock is a sink with a self-loop) that meets
every fairness constraint (Emerson and Lei 1987; Clarke, Grumberg and Peled,
*Model Checking*, §4.1).  A deadlock is therefore fair exactly when every skill
is idle there.

Three-valued like :mod:`skinet.verify.ctl`: the lower bound of fair-EG uses the
expanded markings only (every path found is real); the upper bound also lets a
frontier marking of ``f`` continue fairly (its successors are unknown).

Steps: under fairness a violation may be delayed arbitrarily long (a skill may
loop before it ends), so no finite bound exists in general; the rank given is
the *fewest* steps to the violation, and the witness is such a shortest path.

Cost: one strongly-connected-component decomposition (Tarjan, in
``scipy.sparse.csgraph``) of the restricted graph per bound, plus one backward
search; both linear in the explored markings and edges.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from skinet.net.build import idle_place
from skinet.system.model import System
from skinet.props.formula import PlaceAtom
from skinet.verify.component import ComponentGraph
from skinet.verify.ctl import UNREACHED, Kripke, Result, place_values
from skinet.verify.scc import strong_components


def idle_atoms(graphs: Sequence[ComponentGraph], system: System) -> list[PlaceAtom]:
    """The fairness constraints (docs/semantics.md §6.2): one per skill of the components, its idle place marked."""
    return [PlaceAtom(g.name, idle_place(k.name)) for g in graphs for k in system.component(g.name).skillset.skills]


def skill_fairness(kripke: Kripke, system: System) -> list[np.ndarray]:
    """One fairness constraint per skill of ``system``: where that skill is idle."""
    return [place_values(kripke.space, a) for a in idle_atoms(kripke.space.components, system)]


class _Graph:
    """The explored graph in compact form: expanded markings as rows, edges sorted by source."""

    def __init__(self, kripke: Kripke):
        self.nodes = np.flatnonzero(kripke.expanded)
        src, dst = kripke.edges()
        inner = kripke.expanded[dst]  # an edge into the frontier cannot lie on a known cycle
        order = np.argsort(src[inner], kind="stable")
        self.src = np.searchsorted(self.nodes, src[inner][order])
        self.dst = np.searchsorted(self.nodes, dst[inner][order])
        self.loop = kripke.loop[self.nodes]


def _graph(kripke: Kripke) -> _Graph:
    cache = kripke.__dict__.get("_fair_graph")
    if cache is None:
        cache = kripke.__dict__["_fair_graph"] = _Graph(kripke)
    return cache


def fair_scc_markings(kripke: Kripke, inside: np.ndarray, fairness: Sequence[np.ndarray]) -> np.ndarray | None:
    """Expanded markings of ``inside`` that lie in a fair SCC of the graph restricted to ``inside``.

    ``None`` when the deadline has expired (the decomposition is one call: it
    is not started late).
    """
    if kripke._expired():
        return None
    g = _graph(kripke)
    out = np.zeros(kripke.space.size, dtype=bool)
    member = inside[g.nodes]
    n = int(np.count_nonzero(member))
    if n == 0:
        return out
    renumber = np.cumsum(member) - 1
    keep = member[g.src] & member[g.dst]
    src, dst = renumber[g.src[keep]], renumber[g.dst[keep]]
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(src, minlength=n), out=indptr[1:])
    count, labels = strong_components(indptr, dst.astype(np.int32))
    nodes = g.nodes[member]
    fair = (np.bincount(labels, minlength=count) > 1) | (np.bincount(labels, weights=g.loop[member], minlength=count) > 0)
    for constraint in fairness:
        fair &= np.bincount(labels, weights=constraint[nodes], minlength=count) > 0
    out[nodes[fair[labels]]] = True
    return out


def fair_eg(
    kripke: Kripke, f_lower: np.ndarray, f_upper: np.ndarray, fairness: Sequence[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Fair EG f as ``(lower, upper)``: where a fair path staying in f provably / possibly exists."""
    sccs = fair_scc_markings(kripke, f_lower, fairness)
    # Past the deadline nothing is proven (lower) and every marking of f may go on fairly (upper).
    lower = np.zeros(kripke.space.size, dtype=bool) if sccs is None else kripke.eu(f_lower, sccs, False)
    if np.array_equal(f_lower, f_upper) and not kripke.frontier.any() and not kripke.cut:
        return lower, lower.copy()
    sccs = fair_scc_markings(kripke, f_upper, fairness)
    if sccs is None:
        return lower, f_upper & kripke.stored
    return lower, kripke.eu(f_upper, sccs | (kripke.frontier & f_upper), True)


def fair_af(kripke: Kripke, g: Result, fairness: Sequence[np.ndarray]) -> Result:
    """Fair AF g, three-valued, without ranks (see :func:`distance_to` for steps)."""
    stored = kripke.stored
    eg_lower, eg_upper = fair_eg(kripke, stored & ~g.upper, stored & ~g.lower, fairness)
    return Result(stored & ~eg_upper, stored & ~eg_lower)


def distance_to(kripke: Kripke, target: np.ndarray) -> np.ndarray:
    """Fewest steps from each stored marking to ``target`` (:data:`UNREACHED` when none is known)."""
    dist = np.full(kripke.space.size, UNREACHED, dtype=np.int32)
    layer = np.flatnonzero(target & kripke.stored)
    dist[layer] = 0
    level = 0
    while layer.size:
        level += 1
        found = []
        for p in kripke.predecessor_chunks(layer):
            p = np.unique(p[dist[p] == UNREACHED])
            dist[p] = level
            found.append(p)
        layer = np.concatenate(found) if found else np.empty(0, dtype=np.int64)
    return dist
