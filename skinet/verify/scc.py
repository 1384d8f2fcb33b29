"""Strongly connected components, without importing scipy for small graphs.

Fair AF (docs/semantics.md §6.2) and the compositional abilities (docs/semantics.md §6.4) decompose
graphs into SCCs.  scipy's ``connected_components`` is fast, but importing
``scipy.sparse.csgraph`` costs 0.15-0.3 s, half the start-up of a one-shot
``skinet unsafe`` on the paper system (63 markings).  Graphs of at most
:data:`SMALL_GRAPH` nodes plus edges are therefore decomposed by an iterative
Tarjan in Python (under 10 ms at that size) unless scipy is already loaded;
larger ones by scipy, imported on first use.  :func:`warm_up` imports scipy
ahead of time when a question may need it, so that the import is not paid
inside an answer's budget.  Both paths give the same partition
(``tests/verify/test_scc.py``); label numbers may differ.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from skinet.verify.component import ComponentGraph

# Nodes plus edges up to which Python's Tarjan is used (when scipy is not loaded yet):
# about 5 ms here, against 0.15-0.3 s for importing scipy (benchmarks/bench_startup.py).
SMALL_GRAPH = 5_000


def scipy_loaded() -> bool:
    return "scipy.sparse.csgraph" in sys.modules


def warm_up(size: int) -> float:
    """Import scipy now if a graph of ``size`` nodes plus edges may have to be decomposed; the seconds it took."""
    if size <= SMALL_GRAPH or scipy_loaded():
        return 0.0
    started = time.perf_counter()
    import scipy.sparse.csgraph  # noqa: F401

    return time.perf_counter() - started


def strong_components(indptr: np.ndarray, indices: np.ndarray) -> tuple[int, np.ndarray]:
    """SCCs of the graph in CSR form (successors of ``v``: ``indices[indptr[v]:indptr[v + 1]]``).

    Returns the number of components and the label of each node (``0..count-1``).
    No edge may be repeated: scipy 1.17's strong components are wrong on a CSR
    matrix with repeated entries (tests/verify/test_scc.py shows it).
    Cost: linear in nodes plus edges.
    """
    n = len(indptr) - 1
    if scipy_loaded() or n + len(indices) > SMALL_GRAPH:
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import connected_components

        graph = csr_matrix((np.ones(len(indices)), indices, indptr), shape=(n, n))
        count, labels = connected_components(graph, directed=True, connection="strong")
        return int(count), labels
    return _tarjan(n, np.asarray(indptr).tolist(), np.asarray(indices).tolist())


def strong_components_of_lists(succ: Sequence[Sequence[int]]) -> tuple[int, np.ndarray]:
    """:func:`strong_components` of a graph given as successor lists (repeats allowed)."""
    unique = [sorted(set(s)) for s in succ]
    indptr = np.zeros(len(unique) + 1, dtype=np.int32)
    np.cumsum([len(s) for s in unique], out=indptr[1:])
    return strong_components(indptr, np.array([t for s in unique for t in s], dtype=np.int32))


def warm_up_for(graphs: Sequence[ComponentGraph] | None) -> float:
    """:func:`warm_up` for exploring the product of ``graphs``: it bounds every graph fair AF decomposes.

    ``None`` (the budget ran out inside a component): scipy is imported anyway.
    Returns the seconds the one-time import took (callers move their deadlines by as much).
    """
    if graphs is None:
        return warm_up(SMALL_GRAPH + 1)
    box = math.prod(g.size for g in graphs)
    return warm_up(box + sum(g.edge_count() * (box // g.size) for g in graphs))


def _tarjan(n: int, ptr: list[int], adj: list[int]) -> tuple[int, np.ndarray]:
    """Tarjan's algorithm with an explicit stack (graphs deeper than Python's recursion limit)."""
    index = [-1] * n
    low = [0] * n
    on_stack = [False] * n
    labels = [-1] * n
    stack: list[int] = []
    counter = count = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack[root] = True
        work = [(root, ptr[root])]
        while work:
            v, i = work[-1]
            if i < ptr[v + 1]:
                work[-1] = (v, i + 1)
                w = adj[i]
                if index[w] < 0:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack[w] = True
                    work.append((w, ptr[w]))
                elif on_stack[w] and index[w] < low[v]:
                    low[v] = index[w]
                continue
            work.pop()
            if work:
                u = work[-1][0]
                if low[v] < low[u]:
                    low[u] = low[v]
            if low[v] == index[v]:
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    labels[w] = count
                    if w == v:
                        break
                count += 1
    return count, np.array(labels, dtype=np.int64)
