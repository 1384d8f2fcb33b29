"""Forced violations: uncontrollable reachability, computed compositionally (docs/semantics.md §6.3).

A step is *uncontrollable* when its transition is a skill outcome
(``k.success.m``, ``k.failure.m``; invariant failures happen inside cascades)
and, as an option, an event.  A marking is *forced* for ``phi`` when
uncontrollable steps alone lead from it to a marking violating ``phi``::

    forced(phi) = least X with X = not phi  or  EX_unc X

These are the weakly forbidden markings of supervisory control (Ramadge and
Wonham; for Petri nets with uncontrollable transitions, Giua, DiCesare and
Silva 1992): no command can rule the violation out.

Components share no place, so what uncontrollable steps reach from a combined
marking is the product of what each component reaches alone, and distances
add up.  Each component is searched alone (:func:`uncontrollable_reach`,
memoised per net and marking); a property then only needs, per component it
mentions, the *valuations* of its atoms that component can reach, each with
its least distance.  Cost per query: one small breadth-first search per new
component marking, then at most ``prod_i v_i`` evaluations of ``phi``, where
``v_i <= 2^(atoms of phi on component i)`` is the number of distinct
valuations component ``i`` reaches.  No product exploration, ever.

Examples:
    >>> from skinet.system.load import load_system
    >>> system, _ = load_system("skillsets/mobile_manip.toml")
    >>> m = system.initial_marking()
    >>> forced(system, m, system.property("stowed_drive")) is None
    True
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from itertools import product

import numpy as np

from skinet.net.petrinet import PetriNet, Transition
from skinet.net.semantics import stable_successors
from skinet.props.evaluate import evaluate
from skinet.props.formula import PlaceAtom, Property
from skinet.lang.expr import atoms
from skinet.system.model import System
from skinet.verify.component import ComponentGraph

OUTCOMES = frozenset({"success", "failure"})
CACHE_SIZE = 4096  # component markings remembered per net


def uncontrollable_kinds(events: bool) -> frozenset[str]:
    """Transition kinds that make an uncontrollable step (docs/semantics.md §6.3)."""
    return OUTCOMES | {"event"} if events else OUTCOMES


@dataclass(frozen=True)
class Reach:
    """Markings one component reaches from ``root`` by uncontrollable steps alone.

    ``states[i]`` is reached in ``dist[i]`` steps along ``path[i]`` (logical
    transition names), in breadth-first order, so the first state with a
    property is one of the nearest.
    """

    root: int
    states: tuple[int, ...]
    dist: tuple[int, ...]
    path: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class ForcedVerdict:
    """One shortest uncontrollable sequence from a marking to a violation.

    ``witness`` names each step ``skillset:transition``; ``reached`` is the
    violating combined marking at its end (components that did not move keep
    their marking).
    """

    steps: int
    witness: tuple[str, ...]
    reached: Mapping[str, int]


def uncontrollable_reach(net: PetriNet, marking: int, events: bool = False) -> Reach:
    """Breadth-first search of ``net`` from ``marking`` over uncontrollable steps.

    Memoised on the net (least recently used dropped past :data:`CACHE_SIZE`).
    Cost: O(S x T) for the S markings reached and T transitions of the net;
    outcomes end skills, so S is small unless events cycle.
    """
    cache: OrderedDict[tuple[int, bool], Reach] = net.__dict__.setdefault("_unc_reach", OrderedDict())
    key = (marking, events)
    hit = cache.get(key)
    if hit is not None:
        cache.move_to_end(key)
        return hit
    transitions = _uncontrollable_transitions(net, events)
    states, dist, path = [marking], [0], [()]
    index = {marking: 0}
    i = 0
    while i < len(states):
        m = states[i]
        for t in transitions:  # every marking here is stable: no invariant can block an outcome
            if m & t.pre_mask != t.pre_mask:
                continue
            for r in sorted(stable_successors(net, m, t)):
                if r not in index:
                    index[r] = len(states)
                    states.append(r)
                    dist.append(dist[i] + 1)
                    path.append(path[i] + (t.name,))
        i += 1
    reach = Reach(marking, tuple(states), tuple(dist), tuple(path))
    cache[key] = reach
    while len(cache) > CACHE_SIZE:
        cache.popitem(last=False)
    return reach


def _uncontrollable_transitions(net: PetriNet, events: bool) -> tuple[Transition, ...]:
    cache: dict[bool, tuple[Transition, ...]] = net.__dict__.setdefault("_unc_transitions", {})
    if events not in cache:
        kinds = uncontrollable_kinds(events)
        cache[events] = tuple(t for t in net.transitions if t.kind in kinds and not t.controllable)
    return cache[events]


class ForcedOracle:
    """forced(phi) for every property of one system, memoised per relevant marking.

    Use :func:`oracle` to get the one shared by every caller of a system.
    """

    def __init__(self, system: System, events: bool = False):
        self.system = system
        self.events = events
        self._nets = {c.name: c.net for c in system.components}
        self._atoms: dict[Property, dict[str, tuple[PlaceAtom, ...]]] = {}
        self._memo: OrderedDict[tuple, ForcedVerdict | None] = OrderedDict()

    def atoms_of(self, prop: Property) -> dict[str, tuple[PlaceAtom, ...]]:
        """The atoms of ``prop`` per component it mentions."""
        if prop not in self._atoms:
            per: dict[str, list[PlaceAtom]] = {}
            for a in atoms(prop.expr):
                if isinstance(a, PlaceAtom) and a not in per.setdefault(a.skillset, []):
                    per[a.skillset].append(a)
            self._atoms[prop] = {c: tuple(v) for c, v in per.items()}
        return self._atoms[prop]

    def verdict(self, prop: Property, marking: Mapping[str, int]) -> ForcedVerdict | None:
        """The shortest uncontrollable way from ``marking`` to a violation of ``prop``, or None."""
        per = self.atoms_of(prop)
        key = (prop, *(marking[c] for c in per))
        if key in self._memo:
            self._memo.move_to_end(key)
            found = self._memo[key]
        else:
            found = self._memo[key] = self._search(prop, per, marking)
            while len(self._memo) > CACHE_SIZE:
                self._memo.popitem(last=False)
        if found is None:
            return None
        # The memo knows only the components the property mentions; the others keep this marking.
        return ForcedVerdict(found.steps, found.witness, {**marking, **{c: found.reached[c] for c in per}})

    def _search(self, prop: Property, per: Mapping[str, tuple[PlaceAtom, ...]],
                marking: Mapping[str, int]) -> ForcedVerdict | None:
        names = list(per)
        tables = [self._valuations(c, per[c], marking[c]) for c in names]
        best: tuple[int, tuple[int, ...]] | None = None
        for combo in product(*(list(t.items()) for t in tables)):
            cost = sum(entry[1][0] for entry in combo)
            if best is not None and cost >= best[0]:
                continue
            if _violated(prop, per, names, [valuation for valuation, _ in combo]):
                best = (cost, tuple(entry[1][1] for entry in combo))
        if best is None:
            return None
        witness: list[str] = []
        reached = dict(marking)
        for c, i in zip(names, best[1]):
            reach = uncontrollable_reach(self._nets[c], marking[c], self.events)
            witness.extend(f"{c}:{t}" for t in reach.path[i])
            reached[c] = reach.states[i]
        return ForcedVerdict(best[0], tuple(witness), reached)

    def _valuations(self, comp: str, props_atoms: tuple[PlaceAtom, ...],
                    m: int) -> dict[tuple[bool, ...], tuple[int, int]]:
        """Each valuation of ``props_atoms`` the component reaches: (least distance, state index)."""
        net = self._nets[comp]
        bits = _bits(net, props_atoms)
        reach = uncontrollable_reach(net, m, self.events)
        out: dict[tuple[bool, ...], tuple[int, int]] = {}
        for i, (s, d) in enumerate(zip(reach.states, reach.dist)):
            out.setdefault(_valuation(s, bits), (d, i))
        return out


def _bits(net: PetriNet, props_atoms: tuple[PlaceAtom, ...]) -> list[int]:
    return [net.place_index(a.place) for a in props_atoms]


def _valuation(marking: int, bits: list[int]) -> tuple[bool, ...]:
    return tuple(bool(marking >> b & 1) for b in bits)


def _violated(prop: Property, per: Mapping[str, tuple[PlaceAtom, ...]], names: list[str],
              valuations: Iterable[tuple[bool, ...]]) -> bool:
    """Whether ``prop`` fails when each component of ``names`` has its valuation of its atoms."""
    values = {a: v for c, valuation in zip(names, valuations) for a, v in zip(per[c], valuation)}
    return not evaluate(prop.expr, values.__getitem__)


def oracle(system: System, events: bool = False) -> ForcedOracle:
    """The :class:`ForcedOracle` of ``system``, built once per system and option."""
    cache: dict[bool, ForcedOracle] = system.__dict__.setdefault("_forced_oracles", {})
    if events not in cache:
        cache[events] = ForcedOracle(system, events)
    return cache[events]


def forced(system: System, marking: Mapping[str, int], prop: Property, events: bool = False) -> ForcedVerdict | None:
    """forced(``prop``) at ``marking`` with its steps and witness, or None (docs/semantics.md §6.3)."""
    return oracle(system, events).verdict(prop, marking)


def forced_boxes(
    system: System, graphs: Sequence[ComponentGraph], prop: Property, events: bool = False,
) -> list[list[tuple[int, np.ndarray]]]:
    """forced(``prop``) over the product of ``graphs``, as a union of boxes.

    Each box is a list of ``(position in graphs, boolean mask over that
    component's local states)``; a marking of the product is forced when, for
    some box, every listed component's local state is in its mask (components
    not listed are free).  A constant property gives one empty box (every
    marking forced) or none.  ``graphs`` are component graphs whose local
    states are markings of the eventless nets, which share the full nets'
    places.  Cost: one uncontrollable reach per local state of each component
    the property mentions, then one box per violating combination of the
    valuations of its atoms.
    """
    per = oracle(system, events).atoms_of(prop)
    position = {g.name: i for i, g in enumerate(graphs)}
    names = list(per)
    if not names:  # a constant property
        return [] if evaluate(prop.expr, lambda a: False) else [[]]
    reached: list[list[set[tuple[bool, ...]]]] = []  # per mentioned component, per local state
    for c in names:
        g = graphs[position[c]]
        net = system.component(c).net
        bits = _bits(net, per[c])
        reached.append([{_valuation(s, bits) for s in uncontrollable_reach(net, m, events).states} for m in g.states])
    boxes = []
    for combo in product(*(sorted(set().union(*rows)) for rows in reached)):
        if _violated(prop, per, names, combo):
            boxes.append([(position[c], np.array([valuation in r for r in rows], dtype=bool))
                          for c, valuation, rows in zip(names, combo, reached)])
    return boxes


def forced_mask(
    system: System, graphs: Iterable[ComponentGraph], local: Callable[[np.ndarray, int], np.ndarray],
    prop: Property, events: bool = False,
) -> np.ndarray:
    """forced(``prop``) over an explored state space, as one boolean array.

    ``graphs`` are the space's component graphs; ``local(values, i)``
    broadcasts a per-local-state array of component ``i`` over the space.
    Cost: :func:`forced_boxes`, then one array operation per component of each box.
    """
    graphs = list(graphs)
    out = local(np.zeros(graphs[0].size, dtype=bool), 0).copy()
    for box in forced_boxes(system, graphs, prop, events):
        mask = out | True
        for i, values in box:
            mask &= local(values, i)
        out |= mask
    return out
