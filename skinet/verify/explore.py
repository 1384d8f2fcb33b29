"""Breadth-first exploration of the eventless union net (SPEC §6).

The union's stable-marking graph is the asynchronous product of its
components' graphs (:mod:`skinet.verify.component`).  A global marking is a
mixed-radix *code* over the product box ``n_1 x ... x n_k`` (``n_i`` stable
markings of component ``i``); each layer's successors are generated with
vectorised arithmetic on codes, and a dense ``depth`` array over the box
records what has been seen.  Work per layer is linear in the layer's edges, so
exploration stops honestly between layers when the time budget runs out.
Memory: 6 bytes per box element (depth, and a scratch array that deduplicates
new codes), 8 bytes per marking of the current and next layers, and
temporaries bounded by expanding a layer in chunks.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from skinet.errors import SkinetError
from skinet.net.semantics import steps
from skinet.system import System
from skinet.verify.component import ComponentGraph, explore_component

UNSEEN = -1
DEFAULT_MAX_BOX = 1 << 30
CHUNK = 1 << 13  # codes expanded at once: bounds the temporaries of one layer


class ExplorationTooLarge(SkinetError):
    """The product box exceeds the configured cap."""


@dataclass
class StateSpace:
    """The explored part of the product.

    ``depth[c]`` is the breadth-first distance of code ``c`` (``-1`` when not
    reached).  Markings at depth ``<= expanded_depth`` have all their
    successors stored; the others stored are the *frontier* (empty when
    ``complete``).
    """

    components: list[ComponentGraph]
    shape: tuple[int, ...]
    strides: tuple[int, ...]
    depth: np.ndarray
    expanded_depth: int
    complete: bool
    markings: int
    edges: int
    elapsed: float
    layers: list[int]  # number of markings per depth

    @property
    def box(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64)) if self.shape else 1

    def stored(self) -> np.ndarray:
        return self.depth >= 0

    def expanded(self) -> np.ndarray:
        return (self.depth >= 0) & (self.depth <= self.expanded_depth)

    def frontier(self) -> np.ndarray:
        return self.depth > self.expanded_depth

    def code(self, marking: Mapping[str, int]) -> int | None:
        """Code of a combined marking, or ``None`` when a component never reaches it."""
        c = 0
        for g, stride in zip(self.components, self.strides):
            i = g.index.get(marking[g.name])
            if i is None:
                return None
            c += i * stride
        return c

    def digits(self, codes: np.ndarray, i: int) -> np.ndarray:
        return (codes // self.strides[i]) % self.shape[i]

    def marking(self, code: int) -> dict[str, int]:
        return {g.name: g.states[(code // s) % n] for g, s, n in zip(self.components, self.strides, self.shape)}

    def local(self, values: Sequence[np.ndarray | Sequence[bool]], i: int) -> np.ndarray:
        """Broadcast a per-local-state array of component ``i`` over the box (flat)."""
        arr = np.asarray(values)
        view = [1] * len(self.shape)
        view[i] = self.shape[i]
        return np.broadcast_to(arr.reshape(view), self.shape).reshape(-1)

    def successors(self, code: int) -> list[tuple[int, str]]:
        """Successors of one marking with a label ``skillset:transition``."""
        out: list[tuple[int, str]] = []
        for i, g in enumerate(self.components):
            a = (code // self.strides[i]) % self.shape[i]
            for b in g.succ[a]:
                out.append((code + (b - a) * self.strides[i], f"{g.name}:{g.labels[(a, b)]}"))
            if g.loop[a]:
                out.append((code, f"{g.name}:{g.labels[(a, a)]}"))
        return out


def component_graphs(system: System, marking: Mapping[str, int], event_seeds: bool = True) -> list[ComponentGraph]:
    """Each component's stable graph from its live marking (and its event seeds)."""
    graphs = []
    for comp in system.components:
        m = marking[comp.name]
        seeds: list[int] = []
        if event_seeds:
            for t, results in steps(comp.net, m):
                if t.kind == "event":
                    seeds.extend(results)
        graphs.append(explore_component(comp.name, comp.eventless, [m], seeds))
    return graphs


def explore(
    system: System,
    marking: Mapping[str, int] | None = None,
    *,
    event_seeds: bool = True,
    budget: float | None = None,
    max_depth: int | None = None,
    max_box: int = DEFAULT_MAX_BOX,
    progress: Callable[[int, int, float], None] | None = None,
) -> StateSpace:
    """Explore the eventless union of ``system`` from ``marking`` (default: initial).

    Sources (depth 0) are the live marking and, with ``event_seeds``, every
    marking one firable event leads to.  Stops before expanding a layer when
    ``budget`` seconds have passed or the layer's depth reaches ``max_depth``.
    ``progress(depth, markings, elapsed)`` is called after every layer.
    """
    t0 = time.perf_counter()
    marking = dict(marking or system.initial_marking())
    graphs = component_graphs(system, marking, event_seeds)
    return explore_graphs(graphs, budget=budget, max_depth=max_depth, max_box=max_box, progress=progress, started=t0)


def explore_graphs(
    graphs: Sequence[ComponentGraph],
    *,
    budget: float | None = None,
    max_depth: int | None = None,
    max_box: int = DEFAULT_MAX_BOX,
    progress: Callable[[int, int, float], None] | None = None,
    started: float | None = None,
) -> StateSpace:
    """Breadth-first search of the asynchronous product of ``graphs``.

    Sources are every combination of the components' roots and, for each
    component's seed, the roots with that one component moved to the seed.
    ``started`` (a :func:`time.perf_counter` value, default now) is when the
    budget began; see :func:`explore` for the other arguments.
    """
    t0 = time.perf_counter() if started is None else started
    graphs = list(graphs)
    shape = tuple(g.size for g in graphs)
    box = int(np.prod(shape, dtype=np.int64))
    if box > max_box:
        raise ExplorationTooLarge(
            f"product of component state spaces has {box} markings (components: "
            + ", ".join(f"{g.name}={g.size}" for g in graphs)
            + f"), over the cap of {max_box}"
        )
    strides = tuple(int(np.prod(shape[i + 1:], dtype=np.int64)) for i in range(len(shape)))
    depth = np.full(box, UNSEEN, dtype=np.int16)
    sources = _sources(graphs, strides)
    depth[sources] = 0
    space = StateSpace(graphs, shape, strides, depth, -1, False, len(sources), 0, 0.0, [len(sources)])
    fwd = [g.csr() for g in graphs]
    loops = [g.loop for g in graphs]
    scratch = np.empty(box, dtype=np.int32)  # deduplicates a chunk's new codes
    layer = sources
    d = 0
    while layer.size:
        if (budget is not None and time.perf_counter() - t0 > budget) or (max_depth is not None and d >= max_depth):
            break
        if d + 1 > np.iinfo(depth.dtype).max:
            depth = space.depth = depth.astype(np.int32)
        found = []
        for lo in range(0, layer.size, CHUNK):
            succ, n_edges = _expand(layer[lo:lo + CHUNK], strides, shape, fwd, loops)
            space.edges += n_edges
            new = succ[depth[succ] == UNSEEN]
            idx = np.arange(new.size, dtype=np.int32)
            scratch[new] = idx
            new = new[scratch[new] == idx]
            depth[new] = d + 1
            found.append(new)
        new = np.concatenate(found)
        if new.size:
            space.layers.append(int(new.size))
        space.markings += int(new.size)
        space.expanded_depth = d
        layer = new
        d += 1
        if progress is not None:
            progress(d, space.markings, time.perf_counter() - t0)
    space.complete = layer.size == 0
    if space.complete:
        space.expanded_depth = len(space.layers) - 1
    space.elapsed = time.perf_counter() - t0
    return space


def _sources(graphs: list[ComponentGraph], strides: tuple[int, ...]) -> np.ndarray:
    """Codes of the roots and of every event seed (one component off its root)."""
    base = [np.array(g.roots, dtype=np.int64) * s for g, s in zip(graphs, strides)]
    codes = {0}
    for b in base:
        codes = {c + x for c in codes for x in b.tolist()}
    out = set(codes)
    for i, g in enumerate(graphs):
        for seed in g.seeds:
            for c in codes:
                out.add(c - (c // strides[i] % g.size) * strides[i] + seed * strides[i])
    return np.array(sorted(out), dtype=np.int64)


def unique_codes(codes: np.ndarray) -> np.ndarray:
    """Sorted distinct values of ``codes``."""
    codes = np.sort(codes)
    if codes.size > 1:
        codes = codes[np.concatenate(([True], codes[1:] != codes[:-1]))]
    return codes


def expand_codes(
    codes: np.ndarray, strides: Sequence[int], shape: Sequence[int],
    csr: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
) -> np.ndarray:
    """Every non-loop neighbour code of ``codes`` along each component (with repeats)."""
    return expand_edges(codes, strides, shape, csr, sources=False)[1]


def expand_edges(
    codes: np.ndarray, strides: Sequence[int], shape: Sequence[int],
    csr: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], sources: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """``(sources, targets)`` of every non-loop edge leaving ``codes`` (sources empty unless asked)."""
    src, dst = [], []
    for i, (ptr, targets, deg) in enumerate(csr):
        digit = (codes // strides[i]) % shape[i]
        cnt = deg[digit]
        total = int(cnt.sum())
        if total == 0:
            continue
        if sources:
            src.append(np.repeat(codes, cnt))
        first = np.repeat(ptr[digit] - np.cumsum(cnt) + cnt, cnt)
        dst.append(np.repeat(codes - digit * strides[i], cnt) + targets[first + np.arange(total)] * strides[i])
    empty = np.empty(0, dtype=np.int64)
    return (np.concatenate(src) if src else empty), (np.concatenate(dst) if dst else empty)


def _expand(layer, strides, shape, fwd, loops) -> tuple[np.ndarray, int]:
    """Successor codes of ``layer`` and the number of distinct edges leaving it."""
    succ = expand_codes(layer, strides, shape, fwd)
    any_loop = np.zeros(layer.size, dtype=bool)
    for i, loop in enumerate(loops):
        any_loop |= loop[(layer // strides[i]) % shape[i]]
    return succ, int(succ.size + any_loop.sum())
