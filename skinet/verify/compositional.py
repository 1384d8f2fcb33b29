"""Literal and fair AF at single markings of systems too large to explore (docs/semantics.md §6.2, §6.4).

``AF not phi`` fails at ``m`` exactly when some path from ``m`` stays in
``phi`` forever (``EG phi``; fair: a path on which every skill is idle
infinitely often).  The union's graph is the asynchronous product of its
components, and ``phi`` mentions a few of them, ``M``; the others, ``U``,
never change it.  An infinite path either ends in a global deadlock or
repeats a product cycle, whose projection on every component is a closed walk
(possibly standing still).  Hence, with ``R`` the markings of the
``M``-product reachable from ``m`` through ``phi`` and each ``U`` component's
own reachable graph:

* literal ``EG phi`` at ``m``  iff  ``R`` has a cycle (a self-loop counts), or
  some ``U`` component can reach a cycle, or every group can reach a local
  deadlock (a global deadlock inside ``phi``);
* fair ``EG phi`` at ``m``  iff  every group can *park* (reach a state where
  all its skills are idle, and stop) or *cycle fairly* (reach a strongly
  connected component with an edge that holds an idle state of each of its
  skills), and at least one group cycles; or every group can reach a local
  deadlock where all its skills are idle (a fair deadlock).

Each condition is decided on the ``M``-product (a few thousand markings for
a property over two skillsets) and on the components' own graphs, so verdicts
for the successors of the live marking need no global exploration, whatever
the number of components.  Exact, not an approximation: when the
``M``-product exceeds ``max_states`` or the deadline passes, the verdict is
*undecided*, never safe.  ``steps``/witness of a dangerous verdict: the
fewest steps to a violation (moves of ``M`` only).  Cost: linear in the
``M``-product restricted to ``phi`` plus the components' graphs (memoised).
"""

from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from skinet.lang.expr import atoms
from skinet.net.build import idle_place
from skinet.net.semantics import steps
from skinet.props.evaluate import evaluate
from skinet.props.formula import PlaceAtom, Property
from skinet.system.model import System
from skinet.verify.algorithm1 import PredictionVerdict
from skinet.verify.component import ComponentGraph, explore_component
from skinet.verify.explore import Deadline
from skinet.verify.scc import strong_components_of_lists

MAX_STATES = 1 << 18  # M-product markings searched per verdict
CACHE_SIZE = 4096


@dataclass(frozen=True)
class Abilities:
    """What a group of components can do forever from its start, inside phi for M."""

    cycle: bool  # reach a cycle (literal)
    fair_cycle: bool  # reach a cycle visiting an idle state of each of its skills
    park: bool  # reach a state where all its skills are idle
    dead: bool  # reach a local deadlock
    fair_dead: bool  # reach a local deadlock where all its skills are idle
    longest: int = 0  # steps of the longest path from the start (when no cycle is reachable)


class CompositionalOracle:
    """Verdicts of literal or fair ``AF not phi`` per marking; see the module docstring."""

    def __init__(self, system: System, max_states: int = MAX_STATES):
        self.system = system
        self.max_states = max_states
        self._memo: OrderedDict[tuple, PredictionVerdict] = OrderedDict()
        self._inside_memo: OrderedDict[tuple, tuple] = OrderedDict()  # per property and M-marking
        self._own: dict[tuple[str, int], tuple[Abilities, int]] = {}  # per component and local marking
        self._graphs: dict[str, list[ComponentGraph]] = {}
        self._idle = {c.name: [1 << c.eventless.place_index(idle_place(k.name)) for k in c.skillset.skills]
                      for c in system.components}
        self._mentioned = {p.name: sorted({a.skillset for a in atoms(p.expr) if isinstance(a, PlaceAtom)},
                                          key=[c.name for c in system.components].index)
                           for p in system.properties}

    def verdict(self, prop: Property, marking: Mapping[str, int], af: str = "fair",
                deadline: Deadline | None = None) -> PredictionVerdict:
        key = (prop.name, af, *(marking[c.name] for c in self.system.components))
        if key in self._memo:
            self._memo.move_to_end(key)
            return self._memo[key]
        try:
            found = self._decide(prop, marking, af, deadline or Deadline())
        except KeyError:  # a transient marking: not a state of the stable graph
            found = PredictionVerdict("undecided")
        if found.status != "undecided":
            self._memo[key] = found
            while len(self._memo) > CACHE_SIZE:
                self._memo.popitem(last=False)
        return found

    def remember(self, graphs: Sequence[ComponentGraph]) -> None:
        """Component graphs already explored (the live marking's): their states need no new search."""
        for g in graphs:
            known = self._graphs.setdefault(g.name, [])
            if all(g is not k for k in known):
                known.insert(0, g)
                del known[4:]

    def _graph(self, name: str, m: int) -> tuple[ComponentGraph, int]:
        """A graph holding local marking ``m`` (everything reachable from it) and its index there.

        Raises :class:`KeyError` for a transient ``m`` (stable markings only).
        """
        for g in self._graphs.get(name, ()):
            if m in g.index:
                return g, g.index[m]
        g = explore_component(name, self.system.component(name).eventless, [m])
        self.remember([g])
        return g, g.index[m]

    def _decide(self, prop: Property, marking: Mapping[str, int], af: str, deadline: Deadline) -> PredictionVerdict:
        names = self._mentioned[prop.name]
        key = (prop.name, *(marking[n] for n in names))
        found = self._inside_memo.get(key)
        if found is None:
            if deadline.expired():
                return PredictionVerdict("undecided")
            where = [self._graph(n, marking[n]) for n in names]
            found = self._inside(prop, names, [g for g, _ in where], [i for _, i in where], deadline)
            if found is None:
                return PredictionVerdict("undecided")
            self._inside_memo[key] = found
            while len(self._inside_memo) > CACHE_SIZE:
                self._inside_memo.popitem(last=False)
        inside, dist, witness = found
        if dist is not None and dist == 0:
            return PredictionVerdict("dangerous", 0, ())
        groups = [inside]
        longest = 0
        for c in self.system.components:
            if c.name in names:
                continue
            own = self._own.get((c.name, marking[c.name]))
            if own is None:
                if deadline.expired():
                    return PredictionVerdict("undecided")
                own = self._own[(c.name, marking[c.name])] = _abilities(*self._graph(c.name, marking[c.name]),
                                                                        self._idle[c.name])
            groups.append(own[0])
            longest += own[1]
        if af == "literal":
            forever = any(a.cycle for a in groups) or all(a.dead for a in groups)
        else:
            forever = (all(a.park or a.fair_cycle for a in groups) and any(a.fair_cycle for a in groups)) or all(
                a.fair_dead for a in groups)
        if forever:
            return PredictionVerdict("safe")
        if af == "literal":  # steps: the bound, as the global fixpoint's rank (no cycle anywhere)
            dist = 1 + inside.longest + longest
        return PredictionVerdict("dangerous", dist, witness)

    def _inside(self, prop: Property, names: Sequence[str], graphs: Sequence[ComponentGraph], starts: Sequence[int],
                deadline: Deadline):
        """The M-product inside phi from the start: its abilities, and the fewest steps out of phi."""
        shape = tuple(g.size for g in graphs)
        if int(np.prod(shape, dtype=np.float64)) > self.max_states:
            return None
        by_name = dict(zip(names, range(len(graphs))))

        def atom(a: PlaceAtom) -> np.ndarray:  # the atom over the M box
            i = by_name[a.skillset]
            bit = 1 << graphs[i].net.place_index(a.place)
            view = [1] * len(shape)
            view[i] = shape[i]
            return np.array([bool(m & bit) for m in graphs[i].states]).reshape(view)

        table = np.broadcast_to(np.asarray(evaluate(prop.expr, atom), dtype=bool), shape)

        def phi(state: tuple[int, ...]) -> bool:
            return bool(table[state])

        start = tuple(starts)
        if not phi(start):
            return Abilities(False, False, False, False, False, 0), 0, ()
        index = {start: 0}
        order = [start]
        parent: dict[tuple[int, ...], tuple[tuple[int, ...], str]] = {}
        succ: list[list[int]] = []
        loop: list[bool] = []
        exit_at: tuple[tuple[int, ...], str] | None = None  # first step out of phi (breadth-first: fewest)
        queue = deque([start])
        while queue:
            if len(order) > self.max_states or deadline.expired():
                return None
            s = queue.popleft()
            out: list[int] = []
            looped = False
            for i, g in enumerate(graphs):
                a = s[i]
                looped |= bool(g.loop[a])
                for b in g.succ[a]:
                    t = s[:i] + (b,) + s[i + 1:]
                    if t not in index:
                        if not phi(t):
                            if exit_at is None:
                                exit_at = (s, f"{g.name}:{g.labels[(a, b)]}")
                            continue
                        index[t] = len(order)
                        order.append(t)
                        parent[t] = (s, f"{g.name}:{g.labels[(a, b)]}")
                        queue.append(t)
                    out.append(index[t])
            succ.append(out)
            loop.append(looped)
        masks = [self._idle[n] for n in names]

        def local_states(state: tuple[int, ...]) -> list[int]:
            return [g.states[i] for g, i in zip(graphs, state)]

        dead = [not out and not lp and all(not g.succ[i] and not g.loop[i] for g, i in zip(graphs, s))
                for s, out, lp in zip(order, succ, loop)]
        abilities = _abilities_of(
            len(order), succ, np.array(loop, dtype=bool), np.array(dead, dtype=bool),
            [[all(m & bit for bit in mask) for m, mask in zip(local_states(s), masks)] for s in order],
            [[bool(m & bit) for m, mask in zip(local_states(s), masks) for bit in mask] for s in order],
        )
        if not abilities.cycle:
            abilities = replace(abilities, longest=_longest(len(order), succ))
        if exit_at is None:
            return abilities, None, ()
        path: list[str] = [exit_at[1]]
        s = exit_at[0]
        while s in parent:
            s, label = parent[s]
            path.append(label)
        return abilities, len(path), tuple(reversed(path))


def _longest(n: int, succ: Sequence[Sequence[int]]) -> int:
    """Edges on the longest path from node 0 of an acyclic graph (Kahn's order, then one pass)."""
    indeg = [0] * n
    for out in succ:
        for t in out:
            indeg[t] += 1
    order = [v for v in range(n) if indeg[v] == 0]
    for v in order:
        for t in succ[v]:
            indeg[t] -= 1
            if indeg[t] == 0:
                order.append(t)
    best = [-1] * n
    best[0] = 0
    for v in order:
        if best[v] >= 0:
            for t in succ[v]:
                best[t] = max(best[t], best[v] + 1)
    return max(best)


def _abilities(g: ComponentGraph, start: int, idle_bits: Sequence[int]) -> tuple[Abilities, int]:
    """Abilities of one component from local state ``start``, and its longest path when acyclic."""
    index = {start: 0}
    nodes = [start]
    for a in nodes:  # grows while iterating: breadth-first reachability
        for b in g.succ[a]:
            if b not in index:
                index[b] = len(nodes)
                nodes.append(b)
    succ = [[index[b] for b in g.succ[a]] for a in nodes]
    loop = g.loop[nodes]
    dead = np.array([not s and not lp for s, lp in zip(succ, loop)], dtype=bool)
    states = [g.states[a] for a in nodes]
    found = _abilities_of(
        len(nodes), succ, np.asarray(loop, dtype=bool), dead,
        [[all(m & bit for bit in idle_bits)] for m in states],
        [[bool(m & bit) for bit in idle_bits] for m in states],
    )
    return found, (0 if found.cycle else _longest(len(nodes), succ))


def _abilities_of(n: int, succ: Sequence[Sequence[int]], loop: np.ndarray, dead: np.ndarray,
                  all_idle: Sequence[Sequence[bool]], idle: Sequence[Sequence[bool]]) -> Abilities:
    """Cycles, fair cycles, parking and deadlocks of a graph whose nodes are all reachable."""
    count, labels = strong_components_of_lists(succ)
    size = np.bincount(labels, minlength=count)
    cyclic = (size > 1) | (np.bincount(labels, weights=loop, minlength=count) > 0)
    idle_arr = np.array(idle, dtype=bool).reshape(n, -1)
    fair = cyclic.copy()
    for k in range(idle_arr.shape[1]):
        fair &= np.bincount(labels, weights=idle_arr[:, k], minlength=count) > 0
    parked = np.array([all(x) for x in all_idle], dtype=bool)
    return Abilities(
        cycle=bool(cyclic.any()), fair_cycle=bool(fair.any()), park=bool(parked.any()),
        dead=bool(dead.any()), fair_dead=bool((dead & parked).any()),
    )


def one_step(system: System, marking: Mapping[str, int]) -> Iterator[dict[str, int]]:
    """Every marking one step (transition and cascade, events included) leads to from ``marking``."""
    for comp in system.components:
        for _, results in steps(comp.net, marking[comp.name]):
            for m in results:
                yield {**marking, comp.name: m}


def compositional_oracle(system: System) -> CompositionalOracle:
    """The :class:`CompositionalOracle` of ``system``, built once per system."""
    cache = system.__dict__.get("_compositional_oracle")
    if cache is None:
        cache = system.__dict__["_compositional_oracle"] = CompositionalOracle(system)
    return cache
