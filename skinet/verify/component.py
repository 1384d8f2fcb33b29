"""Stable-marking graph of one skillset's eventless net (docs/semantics.md §3, §6).

The eventless union net is the asynchronous product of its components
(docs/semantics.md §6), so prediction explores each component alone, here, and combines
them in :mod:`skinet.verify.explore`.  States are stable markings; an edge
``a -> b`` means one step (a non-invariant transition and its invariant
cascade) leads from ``a`` to ``b``.  Complexity: O(S x T) firings for S
stable markings and T transitions.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from skinet.net.petrinet import PetriNet
from skinet.net.semantics import stabilize, steps


@dataclass
class ComponentGraph:
    """Reachable stable markings of one net and the steps between them.

    ``dist`` is the breadth-first distance from the roots, ``dist_seed`` from
    the roots and the event seeds together (both -1 when unreachable that way).
    Successor lists are distinct and exclude self-loops, kept in ``loop``.
    """

    name: str
    net: PetriNet
    states: list[int]
    index: dict[int, int]
    succ: list[list[int]]
    loop: np.ndarray  # bool per state: has a step back to itself
    labels: dict[tuple[int, int], str]  # one transition name per edge
    dist: np.ndarray
    dist_seed: np.ndarray
    roots: list[int]
    seeds: list[int]
    _csr: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict, repr=False)

    @property
    def size(self) -> int:
        return len(self.states)

    def csr(self, reverse: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ptr, targets, degree)`` of the successor (or predecessor) lists."""
        key = "rev" if reverse else "fwd"
        if key not in self._csr:
            lists: list[list[int]] = self.succ
            if reverse:
                lists = [[] for _ in self.states]
                for a, targets in enumerate(self.succ):
                    for b in targets:
                        lists[b].append(a)
            deg = np.array([len(x) for x in lists], dtype=np.int64)
            ptr = np.zeros(len(lists) + 1, dtype=np.int64)
            np.cumsum(deg, out=ptr[1:])
            flat = np.array([b for x in lists for b in x], dtype=np.int64)
            self._csr[key] = (ptr, flat, deg)  # one assignment: graphs are shared between threads
        return self._csr[key]

    def edge_count(self) -> int:
        """Distinct (marking, successor) pairs, self-loops included."""
        return sum(len(s) for s in self.succ) + int(self.loop.sum())


CACHE_SIZE = 64  # component graphs remembered per net


class Expired(Exception):
    """The deadline passed while a component was being explored."""


def explore_component(
    name: str, eventless: PetriNet, roots: Iterable[int], seeds: Iterable[int] = (),
    expired: Callable[[], bool] | None = None,
) -> ComponentGraph:
    """Breadth-first search of ``eventless`` from ``roots`` and ``seeds``.

    Roots and seeds are stabilized first (a transient marking is replaced by
    the stable markings its cascade ends in).  The last :data:`CACHE_SIZE`
    graphs of each net are memoised: a live system usually moves one
    component at a time, so the others' graphs are reused.  Cached graphs are
    shared: treat them as read-only.  Safe under threads (at worst a graph is
    computed twice).  ``expired`` is asked every few states: when it says so,
    :class:`Expired` is raised and nothing is memoised.
    """
    key = (name, frozenset(roots), frozenset(seeds))
    # Cached on the (frozen, immutable) net itself, as PetriNet caches its place index.
    cache: dict[tuple[str, frozenset[int], frozenset[int]], ComponentGraph]
    cache = eventless.__dict__.setdefault("_component_graphs", {})
    graph = cache.pop(key, None)
    if graph is None:
        graph = _explore(name, eventless, key[1], key[2], expired)
        for stale in list(cache)[: max(0, len(cache) + 1 - CACHE_SIZE)]:
            cache.pop(stale, None)  # least recently used first
    cache[key] = graph
    return graph


def forget_component_graphs(eventless: PetriNet) -> None:
    """Drop the graphs memoised for ``eventless`` (for cold measurements)."""
    eventless.__dict__.pop("_component_graphs", None)


def stub_component(name: str, eventless: PetriNet, marking: int) -> ComponentGraph:
    """A graph of the one stable ``marking`` whose successors are unknown (never a deadlock once unexpanded)."""
    return ComponentGraph(name, eventless, [marking], {marking: 0}, [[]], np.zeros(1, dtype=bool), {},
                          np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), [0], [])


def _explore(
    name: str, eventless: PetriNet, roots: Iterable[int], seeds: Iterable[int], expired: Callable[[], bool] | None
) -> ComponentGraph:
    root_states = sorted({s for r in roots for s in stabilize(eventless, r)})
    seed_states = sorted({s for r in seeds for s in stabilize(eventless, r)} - set(root_states))
    states: list[int] = []
    index: dict[int, int] = {}
    succ: list[list[int]] = []
    loops: list[bool] = []
    labels: dict[tuple[int, int], str] = {}

    def add(m: int) -> int:
        if m not in index:
            index[m] = len(states)
            states.append(m)
            succ.append([])
            loops.append(False)
        return index[m]

    for m in root_states + seed_states:
        add(m)
    i = 0
    while i < len(states):
        if expired is not None and i % 64 == 0 and expired():
            raise Expired(name)
        m = states[i]
        targets: dict[int, None] = {}
        for t, results in steps(eventless, m):
            for r in results:
                j = add(r)
                labels.setdefault((i, j), t.name)
                if j == i:
                    loops[i] = True
                else:
                    targets[j] = None
        succ[i] = list(targets)
        i += 1
    roots_i = [index[m] for m in root_states]
    seeds_i = [index[m] for m in seed_states]
    return ComponentGraph(
        name, eventless, states, index, succ, np.array(loops, dtype=bool), labels,
        _bfs(succ, roots_i), _bfs(succ, roots_i + seeds_i), roots_i, seeds_i,
    )


def _bfs(succ: list[list[int]], sources: list[int]) -> np.ndarray:
    dist = np.full(len(succ), -1, dtype=np.int64)
    layer = list(dict.fromkeys(sources))
    for s in layer:
        dist[s] = 0
    d = 0
    while layer:
        d += 1
        nxt = []
        for a in layer:
            for b in succ[a]:
                if dist[b] < 0:
                    dist[b] = d
                    nxt.append(b)
        layer = nxt
    return dist
