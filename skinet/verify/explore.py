"""Breadth-first exploration of the eventless union net (docs/semantics.md §6.1, §6.4).

The union's stable-marking graph is the asynchronous product of its
components' graphs (:mod:`skinet.verify.component`).  A global marking is a
mixed-radix *code* over the product box ``n_1 x ... x n_k`` (``n_i`` stable
markings of component ``i``).  Breadth-first depth needs no search (docs/semantics.md
§6.4): from the live marking it is the sum of the components' depths, and an
event seed moves one component only, so with seeds

    depth(c) = min(D, min_i (D - d_i(c_i) + s_i(c_i)))    D = sum_i d_i(c_i)

where ``d_i`` is component ``i``'s distance from its roots and ``s_i`` from its
roots and seeds (a component state reached from seeds only makes exactly one
component use its seed).  The number of markings per layer follows by a
dynamic programme over (sum, largest saving), so the depth that fits the memory
limit and the time budget is chosen *before* anything is allocated; the stored
markings (depth <= expanded depth + 1) are then enumerated in code order with
pruning, chunk by chunk, checking the deadline per chunk.

Storage follows what is stored (docs/semantics.md §6.1): the *index space* of every array
over markings is either the box itself (``codes is None``: index = code, a
byte per box element per boolean array; chosen when the stored markings fill
most of the box) or the positions in the sorted array ``codes`` of stored
codes (8 bytes per stored marking plus a byte per boolean array; code -> index
by binary search).  Cost: O(n) for n stored markings (box mode with a full box:
O(k) plus the arrays).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from skinet.net.semantics import steps
from skinet.system.model import System
from skinet.verify.component import ComponentGraph, Expired, explore_component, stub_component

CHUNK = 1 << 15  # markings handled at once: bounds the temporaries of every pass
DEFAULT_MEMORY_LIMIT = 1 << 30
MAX_CODE = 1 << 62  # codes are int64
# Planning estimates (bytes): per stored marking in sparse mode, per box element in
# box mode, and per property on top of both; measured by benchmarks/bench_memory.py.
SPARSE_BYTES, BOX_BYTES, PROPERTY_BYTES = 32, 3.2, 2.5
# Seconds per stored marking and per property (exploration + fixpoints), for planning
# the depth that fits the time budget; per-chunk deadline checks make it safe.
SECONDS_PER_MARKING = 1e-7
FIXPOINT_FACTOR = 1.5  # Kripke structure and atoms, in units of the enumeration's cost
PROBE = 1 << 17  # markings enumerated before the rate is measured
EDGE_BYTES = 80  # an edge list held for fair AF: sources, targets, their sorted copies, the SCC matrix

TruncatedBy = str  # "budget" | "memory" | "depth"


class Deadline:
    """A point in :func:`time.perf_counter` time; ``None`` never expires."""

    def __init__(self, at: float | None = None) -> None:
        self.at = at
        self.hit = False

    @classmethod
    def after(cls, seconds: float | None, started: float | None = None) -> Deadline:
        if seconds is None:
            return cls(None)
        return cls((time.perf_counter() if started is None else started) + seconds)

    def expired(self) -> bool:
        if self.at is not None and time.perf_counter() > self.at:
            self.hit = True
        return self.hit

    def left(self) -> float:
        return float("inf") if self.at is None else self.at - time.perf_counter()


def resident_bytes() -> int:
    """This process's current resident set size (0 where /proc is missing)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096
    except OSError:
        return 0


def peak_resident_bytes() -> int:
    """This process's peak resident set size since its start (``VmHWM``; 0 where /proc is missing).

    Unlike ``getrusage().ru_maxrss``, it does not include the parent's image a
    child process was forked from.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def local_indices(graphs: Sequence[ComponentGraph], marking: Mapping[str, int]) -> list[int] | None:
    """``marking`` as one local state index per component, or ``None`` when it lies outside their product."""
    out = []
    for g in graphs:
        i = g.index.get(marking[g.name])
        if i is None:
            return None
        out.append(i)
    return out


@dataclass
class StateSpace:
    """The explored part of the product.

    Markings at depth ``<= expanded_depth`` have all their successors stored;
    the others stored (depth ``expanded_depth + 1``) are the *frontier*
    (empty when ``complete``).  Arrays over markings use the index space:
    ``index(codes)``/``code_of(indices)`` convert.  ``truncated_by`` says what
    stopped the exploration (``"budget"``, ``"memory"``, ``"depth"``) or is
    ``None``; the fixpoints may still be cut by the budget (see
    :class:`skinet.verify.ctl.Kripke`).
    """

    components: list[ComponentGraph]
    shape: tuple[int, ...]
    strides: tuple[int, ...]
    codes: np.ndarray | None  # sorted stored codes, or None: index = code
    stored_mask: np.ndarray | None  # box mode: stored per code (None: every code stored)
    expanded_depth: int
    complete: bool
    markings: int
    edges: int
    elapsed: float
    layers: list[int]  # number of markings per depth (stored ones)
    truncated_by: TruncatedBy | None = None
    deadline: Deadline = field(default_factory=Deadline, repr=False)
    expanded_mask: np.ndarray | None = field(default=None, repr=False)  # None when complete

    @property
    def box(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64)) if self.shape else 1

    @property
    def size(self) -> int:
        """Length of arrays over the index space."""
        return self.box if self.codes is None else int(self.codes.size)

    def code_of(self, idx: np.ndarray) -> np.ndarray:
        return idx if self.codes is None else self.codes[idx]

    def index(self, codes: np.ndarray) -> np.ndarray:
        """Index of each code, -1 where not stored."""
        codes = np.asarray(codes, dtype=np.int64)
        if self.codes is None:
            if self.stored_mask is None:
                return codes
            return np.where(self.stored_mask[codes], codes, -1)
        if not self.codes.size:
            return np.full(codes.shape, -1)
        if codes.size > 1024:  # sorted needles search several times faster (cache locality)
            order = np.argsort(codes)
            pos = np.empty(codes.shape, dtype=np.int64)
            pos[order] = np.searchsorted(self.codes, codes[order])
        else:
            pos = np.searchsorted(self.codes, codes)
        pos[pos == self.codes.size] = 0
        return np.where(self.codes[pos] == codes, pos, -1)

    def stored(self) -> np.ndarray:
        if self.codes is None and self.stored_mask is not None:
            return self.stored_mask
        return np.broadcast_to(np.True_, (self.size,))

    def expanded(self) -> np.ndarray:
        if self.complete or self.expanded_mask is None:
            return self.stored()
        return self.expanded_mask

    def frontier(self) -> np.ndarray:
        if self.complete:
            return np.broadcast_to(np.False_, (self.size,))
        return self.stored() & ~self.expanded()

    @property
    def depth(self) -> np.ndarray:
        """Breadth-first depth per index (-1 where not stored); computed on demand."""
        out = np.full(self.size, -1, dtype=np.int32)
        for _, idx, depth in self.depth_chunks():
            out[idx] = depth
        return out

    def depth_chunks(self) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
        """``(start, stored indices, their depths)`` chunk by chunk."""
        for lo in range(0, self.size, CHUNK):
            idx = np.arange(lo, min(self.size, lo + CHUNK), dtype=np.int64)
            if self.codes is None and self.stored_mask is not None:
                idx = idx[self.stored_mask[idx]]
            yield lo, idx, depths(self.components, self.strides, self.code_of(idx))

    def explored(self) -> str:
        """What was explored, in words, for a truncation message (``depth -1`` means nothing to a user)."""
        stored = f"{self.markings} marking{'' if self.markings == 1 else 's'} stored"
        if self.complete:
            return f"every layer expanded, {stored}"
        if self.expanded_depth < 0:
            if self.markings <= 1:
                return "only the live marking stored, no layer expanded" if self.markings else "nothing stored"
            return f"{stored}, no layer expanded"
        depths = f"depths 0 to {self.expanded_depth}" if self.expanded_depth else "depth 0"
        return f"{depths} expanded, {stored}"

    def transfer(self, values: np.ndarray, other: StateSpace, fill: object = False) -> np.ndarray:
        """``values`` over this space's index space, moved to ``other``'s (``fill`` elsewhere).

        Markings stored here but not in ``other`` are dropped.
        """
        values = np.broadcast_to(values, (self.size,))
        out = np.full(other.size, fill, dtype=values.dtype)
        mine = np.flatnonzero(self.stored())
        at = other.index(self.code_of(mine))
        out[at[at >= 0]] = values[mine[at >= 0]]
        return out

    def code(self, marking: Mapping[str, int]) -> int | None:
        """Index of a combined marking, or ``None`` when it is not stored."""
        local = local_indices(self.components, marking)
        if local is None:
            return None
        c = sum(i * stride for i, stride in zip(local, self.strides))
        if c >= MAX_CODE:
            return None
        i = int(self.index(np.array([c]))[0])
        return None if i < 0 else i

    def digits(self, idx: np.ndarray, i: int) -> np.ndarray:
        """Component ``i``'s local state at each index."""
        return (self.code_of(np.asarray(idx)) // self.strides[i]) % self.shape[i]

    def marking(self, idx: int) -> dict[str, int]:
        code = int(self.code_of(np.array([idx]))[0])
        return {g.name: g.states[(code // s) % n] for g, s, n in zip(self.components, self.strides, self.shape)}

    def local(self, values: Sequence[np.ndarray | Sequence[bool]], i: int) -> np.ndarray:
        """A per-local-state array of component ``i``, over the index space."""
        arr = np.asarray(values)
        if self.codes is None:
            view = [1] * len(self.shape)
            view[i] = self.shape[i]
            return np.broadcast_to(arr.reshape(view), self.shape).reshape(-1)
        out = np.empty(self.size, dtype=arr.dtype)
        for lo in range(0, self.size, CHUNK):
            out[lo:lo + CHUNK] = arr[self.digits(np.arange(lo, min(self.size, lo + CHUNK)), i)]
        return out

    def successors(self, idx: int) -> list[tuple[int, str]]:
        """Stored successors of one marking (indices) with a label ``skillset:transition``."""
        code = int(self.code_of(np.array([idx]))[0])
        out: list[tuple[int, str]] = []
        for i, g in enumerate(self.components):
            a = (code // self.strides[i]) % self.shape[i]
            for b in g.succ[a]:
                j = int(self.index(np.array([code + (b - a) * self.strides[i]]))[0])
                if j >= 0:
                    out.append((j, f"{g.name}:{g.labels[(a, b)]}"))
            if g.loop[a]:
                out.append((idx, f"{g.name}:{g.labels[(a, a)]}"))
        return out


def component_graphs(
    system: System, marking: Mapping[str, int], event_seeds: bool = True, deadline: Deadline | None = None
) -> list[ComponentGraph]:
    """Each component's stable graph from its live marking (and its event seeds).

    Raises :class:`skinet.verify.component.Expired` when ``deadline`` passes first.
    """
    expired = None if deadline is None or deadline.at is None else deadline.expired
    graphs = []
    for comp in system.components:
        m = marking[comp.name]
        seeds: list[int] = []
        if event_seeds:
            for t, results in steps(comp.net, m):
                if t.kind == "event":
                    seeds.extend(results)
        graphs.append(explore_component(comp.name, comp.eventless, [m], seeds, expired))
    return graphs


def explore(
    system: System,
    marking: Mapping[str, int] | None = None,
    *,
    event_seeds: bool = True,
    budget: float | None = None,
    max_depth: int | None = None,
    memory_limit: int | None = DEFAULT_MEMORY_LIMIT,
    properties: int = 0,
    edges: bool = False,
    progress: Callable[[int, int, float], None] | None = None,
    deadline: Deadline | None = None,
    graphs: Sequence[ComponentGraph] | None = None,
) -> StateSpace:
    """Explore the eventless union of ``system`` from ``marking`` (default: initial).

    Sources (depth 0) are the live marking and, with ``event_seeds``, every
    marking one firable event leads to.  ``graphs``: the components' graphs
    when the caller has them (:func:`component_graphs`).  See
    :func:`explore_graphs`.
    """
    t0 = time.perf_counter()
    deadline = deadline or Deadline.after(budget, t0)
    marking = dict(marking or system.initial_marking())
    try:
        graphs = component_graphs(system, marking, event_seeds, deadline) if graphs is None else graphs
    except Expired:
        # The budget ran out inside a component: only the live marking is known, its successors are not.
        stubs = [stub_component(c.name, c.eventless, marking[c.name]) for c in system.components]
        space = explore_graphs(stubs, max_depth=0, memory_limit=None, started=t0, deadline=deadline)
        space.truncated_by = "budget"
        return space
    return explore_graphs(graphs, max_depth=max_depth, memory_limit=memory_limit, properties=properties,
                          edges=edges, progress=progress, started=t0, deadline=deadline)


def explore_graphs(
    graphs: Sequence[ComponentGraph],
    *,
    budget: float | None = None,
    max_depth: int | None = None,
    memory_limit: int | None = DEFAULT_MEMORY_LIMIT,
    properties: int = 0,
    edges: bool = False,
    progress: Callable[[int, int, float], None] | None = None,
    started: float | None = None,
    deadline: Deadline | None = None,
) -> StateSpace:
    """Breadth-first layers of the asynchronous product of ``graphs``.

    Sources are every combination of the components' roots and, for each
    component's seed, the roots with that one component moved to the seed.
    Expands at most ``max_depth`` layers; stops earlier where the stored
    markings (with ``properties`` mu1 results on top, and the edge list when
    ``edges``: fair AF decomposes the explored graph) would not fit
    ``memory_limit`` bytes (whole process) or the time budget (``budget``
    seconds from ``started``, or ``deadline``).  ``progress(depth, markings,
    elapsed)`` is called as markings are stored.
    """
    t0 = time.perf_counter() if started is None else started
    deadline = deadline or Deadline.after(budget, t0)
    graphs = list(graphs)
    shape = tuple(g.size for g in graphs)
    box = 1
    for n in shape:
        box *= n
    strides = tuple(int(np.prod(shape[i + 1:], dtype=np.int64)) for i in range(len(shape)))
    layers_all = layer_counts(graphs)
    last = len(layers_all) - 1  # deepest layer
    cumulative = np.cumsum(np.array(layers_all, dtype=np.float64))

    def stored_count(e: int) -> float:  # markings stored when layers <= e are expanded
        return float(cumulative[min(e + 1, last)])

    per_box, per_marking = BOX_BYTES + PROPERTY_BYTES * properties, SPARSE_BYTES + PROPERTY_BYTES * properties
    units = FIXPOINT_FACTOR + properties  # time per stored marking, in units of the enumeration's
    per_edges = 0.0  # bytes per stored marking for its edge list
    if edges:
        degree = sum(float(g.csr()[2].mean()) if g.size else 0.0 for g in graphs) + 1
        per_edges = EDGE_BYTES * degree
        units += degree
    room = None if memory_limit is None else memory_limit - resident_bytes()
    rate = SECONDS_PER_MARKING
    for attempt in range(3):
        reasons: list[tuple[int, TruncatedBy]] = []
        if max_depth is not None and max_depth - 1 < last:
            reasons.append((max_depth - 1, "depth"))
        if box >= MAX_CODE:
            reasons.append((-2, "memory"))
        if room is not None:
            fits = [e for e in range(-1, last + 1)
                    if min(box * per_box, stored_count(e) * per_marking) + stored_count(e) * per_edges <= room]
            reasons.append((max(fits) if fits else -2, "memory"))
        if deadline.at is not None:
            left = deadline.left()
            fits = [e for e in range(-1, last + 1) if stored_count(e) * rate * units <= left]
            reasons.append((max(fits) if fits and left > 0 else -1, "budget"))
        expanded_depth, truncated_by = last, None
        for e, why in reasons:
            if e < expanded_depth:
                expanded_depth, truncated_by = e, why
        if expanded_depth < -1:  # not even the sources fit
            return StateSpace(graphs, shape, strides, np.empty(0, dtype=np.int64), None, -1, False, 0, 0,
                              time.perf_counter() - t0, [], truncated_by, deadline)
        complete = expanded_depth >= last
        limit = last if complete else expanded_depth + 1
        n_stored = int(stored_count(limit - 1)) if limit >= 0 else 0
        box_mode = box * per_box <= n_stored * per_marking
        layers = list(layers_all[:limit + 1])
        if box_mode and n_stored == box and complete:
            space = StateSpace(graphs, shape, strides, None, None, expanded_depth, complete, n_stored,
                               _box_edges(graphs, box), 0.0, layers, truncated_by, deadline)
            break
        probe = PROBE if attempt < 2 and deadline.at is not None else None
        space = _store(graphs, strides, box, box_mode, limit, expanded_depth, complete, n_stored, layers,
                       truncated_by, deadline, probe, units, progress, t0)
        if isinstance(space, StateSpace):
            break
        rate = space  # measured seconds per stored marking: plan again
    space.elapsed = time.perf_counter() - t0
    if progress is not None:
        progress(max(0, space.expanded_depth + 1), space.markings, space.elapsed)
    return space


def _store(
    graphs: list[ComponentGraph], strides: tuple[int, ...], box: int, box_mode: bool, limit: int,
    expanded_depth: int, complete: bool, n_stored: int, layers: list[int], truncated_by: TruncatedBy | None,
    deadline: Deadline, probe: int | None, units: float,
    progress: Callable[[int, int, float], None] | None, t0: float,
) -> StateSpace | float:
    """Enumerate and store the markings of depth ``<= limit``.

    With ``probe`` (markings), returns the measured seconds per marking instead
    when the whole answer would not fit the deadline at that rate.
    """
    started = time.perf_counter()
    shape = tuple(g.size for g in graphs)
    chunks: list[np.ndarray] = []
    expanded: list[np.ndarray] = []
    mask = np.zeros(box, dtype=bool) if box_mode else None
    wide = np.zeros(box if box_mode else 0, dtype=bool) if not complete else None
    done = edges = 0
    for codes, depth in enumerate_codes(graphs, strides, limit):
        inner = depth <= expanded_depth
        edges += _chunk_edges(graphs, strides, codes[inner])
        if mask is not None:
            mask[codes] = True
            if wide is not None:
                wide[codes[inner]] = True
        else:
            chunks.append(codes)
            if wide is not None:
                expanded.append(inner)
        done += codes.size
        if progress is not None:
            progress(limit, done, time.perf_counter() - t0)
        if probe is not None and done >= min(probe, n_stored):
            rate = (time.perf_counter() - started) / done
            if rate * (n_stored - done) + rate * n_stored * (units - 1) > deadline.left():
                return rate
            probe = None
        if done < n_stored and deadline.expired():
            # Cut inside a layer: what is stored is kept, nothing is known to be expanded.
            expanded_depth, complete, truncated_by, edges, layers = -1, False, "budget", 0, [done]
            expanded = []
            wide = np.zeros(box if box_mode else 0, dtype=bool)
            break
    if mask is not None and done == box:
        mask = None  # every code stored
    if box_mode:
        stored_codes = None
    else:
        stored_codes = np.concatenate(chunks) if chunks else np.empty(0, dtype=np.int64)
        del chunks
        if wide is not None:
            wide = np.concatenate(expanded) if expanded else np.zeros(stored_codes.size, dtype=bool)
            if wide.size != stored_codes.size:  # cut: nothing expanded
                wide = np.zeros(stored_codes.size, dtype=bool)
    space = StateSpace(graphs, shape, strides, stored_codes, mask, expanded_depth, complete, done, edges, 0.0,
                       layers, truncated_by, deadline, wide)
    return space


def depths(graphs: Sequence[ComponentGraph], strides: Sequence[int], codes: np.ndarray) -> np.ndarray:
    """Breadth-first depth of each code (-1 when unreachable), by the formula above."""
    total = np.zeros(codes.shape, dtype=np.int64)
    saving = np.zeros(codes.shape, dtype=np.int64)
    seeded = np.zeros(codes.shape, dtype=np.int8)  # components reached from their seeds only
    for g, stride in zip(graphs, strides):
        digit = (codes // stride) % g.size
        d, s = g.dist[digit], g.dist_seed[digit]
        own = d >= 0
        total += np.where(own, d, s)
        np.maximum(saving, np.where(own, d - s, 0), out=saving)
        seeded += np.where(own, 0, np.where(s >= 0, 1, 2)).astype(np.int8)
    out = np.where(seeded == 0, total - saving, total)
    out[seeded > 1] = -1
    return out


def layer_counts(graphs: Sequence[ComponentGraph]) -> list[int]:
    """Number of reachable markings per breadth-first depth, without enumerating them.

    Dynamic programme over the components: state (sum, largest saving) for
    markings with every component reached from its roots, and (sum) for
    markings with exactly one component reached from its seeds only.
    Exact (Python integers), O(k x distinct (d, s) pairs x sum x saving).
    """
    s_max = sum(int(np.maximum(g.dist, g.dist_seed).max(initial=0)) for g in graphs) + 1
    g_max = max([int((g.dist - g.dist_seed)[g.dist >= 0].max(initial=0)) for g in graphs] + [0]) + 1
    own = np.zeros((s_max, g_max), dtype=object)
    own[0, 0] = 1
    seeded = np.zeros(s_max, dtype=object)
    for g in graphs:
        new_own = np.zeros_like(own)
        new_seeded = np.zeros_like(seeded)
        pairs: dict[tuple[int, int], int] = {}
        for d, s in zip(g.dist.tolist(), g.dist_seed.tolist()):
            if s < 0:
                continue  # unreachable
            key = (d, d - s) if d >= 0 else (-1, s)
            pairs[key] = pairs.get(key, 0) + 1
        for (d, x), mult in pairs.items():
            if d >= 0:  # reached from the roots, saving x
                n = s_max - d
                new_own[d:, x] += mult * own[:n, :x + 1].sum(axis=1)
                new_own[d:, x + 1:] += mult * own[:n, x + 1:]
                new_seeded[d:] += mult * seeded[:n]
            else:  # reached from the seeds only, at distance x
                new_seeded[x:] += mult * own[:s_max - x, :].sum(axis=1)
        own, seeded = new_own, new_seeded
    counts = [0] * s_max
    for s in range(s_max):
        for x in range(g_max):
            if own[s, x]:
                counts[s - x] += int(own[s, x])
        counts[s] += int(seeded[s])
    while counts and counts[-1] == 0:
        counts.pop()
    return counts


def enumerate_codes(
    graphs: Sequence[ComponentGraph], strides: Sequence[int], limit: int
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``(codes, depths)`` of every marking of depth ``<= limit``, in increasing code order.

    Prefixes are extended one component at a time, a chunk of prefixes at a
    time, and pruned by a lower bound of the depth (the sum of the distances
    from roots and seeds), so the work is close to the number of results.
    """
    k = len(graphs)
    fields = [(g.dist, g.dist_seed, np.arange(g.size, dtype=np.int64) * st) for g, st in zip(graphs, strides)]
    # A state unreachable from roots and seeds counts as two seeded components: pruned.
    weight = [np.where(d >= 0, 0, np.where(s >= 0, 1, 2)).astype(np.int8) for d, s, _ in fields]

    def extend(level: int, code, total, bound, saving, seeded) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        if level == k:
            depth = np.where(seeded == 0, total - saving, total)
            keep = depth <= limit
            yield code[keep], depth[keep]
            return
        d, s, offset = fields[level]
        n = d.size
        own = d >= 0
        s = np.maximum(s, 0)
        step = max(1, CHUNK // n)
        for lo in range(0, code.size, step):
            m = min(step, code.size - lo)
            rep = lambda a: np.repeat(a[lo:lo + m], n)  # noqa: E731
            b = rep(bound) + np.tile(s, m)
            sd = rep(seeded) + np.tile(weight[level], m)
            keep = (b <= limit) & (sd <= 1)
            if not keep.any():
                continue
            yield from extend(
                level + 1,
                (rep(code) + np.tile(offset, m))[keep],
                (rep(total) + np.tile(np.where(own, d, s), m))[keep],
                b[keep],
                np.maximum(rep(saving), np.tile(np.where(own, d - s, 0), m))[keep],
                sd[keep],
            )

    zero = np.zeros(1, dtype=np.int64)
    yield from extend(0, zero, zero, zero, zero, np.zeros(1, dtype=np.int8))


def _chunk_edges(graphs: Sequence[ComponentGraph], strides: Sequence[int], codes: np.ndarray) -> int:
    """Distinct edges leaving ``codes`` (self-loops included)."""
    total = 0
    loop = np.zeros(codes.size, dtype=bool)
    for g, stride in zip(graphs, strides):
        digit = (codes // stride) % g.size
        total += int(g.csr()[2][digit].sum())
        loop |= g.loop[digit]
    return total + int(loop.sum())


def _box_edges(graphs: Sequence[ComponentGraph], box: int) -> int:
    """Edges of the whole box: every component's edges times the others' states, plus loops."""
    total = sum(int(g.csr()[2].sum()) * (box // g.size) for g in graphs)
    no_loop = 1
    for g in graphs:
        no_loop *= int(g.size - g.loop.sum())
    return total + box - no_loop


def unique_codes(codes: np.ndarray, presorted: bool = False) -> np.ndarray:
    """Sorted distinct values of ``codes``."""
    if not presorted:
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
