"""Fair EG and fair AF against a direct definition (docs/semantics.md §6.2).

The reference never decomposes into SCCs: on the graph restricted to ``f``
(a deadlock is a sink with a self-loop) it takes the boolean transitive
closure ``R``; a state ``v`` of ``f`` lies on a fair cycle when ``R[v, v]``
and, for every fairness constraint, some state ``u`` of it has ``R[v, u]``
and ``R[u, v]`` (then ``v -> u_1 -> v -> u_2 -> ... -> v`` is a cycle inside
``f`` through every constraint); fair-EG ``f`` holds at ``s`` when ``s`` is
in ``f`` and is, or reaches inside ``f``, such a ``v``.  Fair AF ``g`` is
``not`` fair-EG ``not g``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Collection, Hashable, Iterable, Sequence
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skinet.system.load import load_system
from skinet.net.build import idle_place
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.system.model import System
from skinet.verify.ctl import UNREACHED, Kripke, Result
from skinet.verify.component import ComponentGraph
from skinet.verify.explore import StateSpace, explore_graphs
from skinet.verify.fair import distance_to, fair_af, fair_eg, fair_scc_markings, skill_fairness
from skinet.verify.predict import forecast
from tests.verify.test_ctl import Explicit, as_set, codes_of, make_graph, systems
from tests.verify.test_predict import Explicit as UnionGraph
from tests.verify.test_predict import ovens

ROOT = Path(__file__).resolve().parents[2]


def fair_eg_reference(
    states: Iterable[Hashable], succ: Callable[[Hashable], Iterable[Hashable]],
    f: Collection[Hashable], fairness: Sequence[Collection[Hashable]],
) -> tuple[set, set]:
    """``(fair-EG f, states of f on a fair cycle inside f)`` by transitive closure."""
    order = list(states)
    index = {s: i for i, s in enumerate(order)}
    n = len(order)
    inside = np.array([s in f for s in order], dtype=bool)
    reach = np.zeros((n, n), dtype=bool)
    for s in order:
        for t in succ(s):
            reach[index[s], index[t]] = True
    reach &= inside[:, None] & inside[None, :]
    for k in range(n):  # Warshall: paths of length >= 1 inside f
        reach |= np.outer(reach[:, k], reach[k, :])
    cycle = inside & reach.diagonal()
    both_ways = reach & reach.T
    for constraint in fairness:
        member = np.array([s in constraint for s in order], dtype=bool)
        cycle &= both_ways[:, member].any(axis=1)
    holds = inside & (cycle | (reach & cycle[None, :]).any(axis=1))
    return {order[i] for i in np.flatnonzero(holds)}, {order[i] for i in np.flatnonzero(cycle)}


def bfs_distances(states: Iterable[Hashable], succ: Callable[[Hashable], Iterable[Hashable]],
                  target: Collection[Hashable]) -> dict:
    """Fewest steps from each state to ``target`` (absent when it is never reached)."""
    preds: dict = {}
    for s in states:
        for t in succ(s):
            preds.setdefault(t, set()).add(s)
    dist = {s: 0 for s in states if s in target}
    queue = deque(dist)
    while queue:
        t = queue.popleft()
        for s in preds.get(t, ()):
            if s not in dist:
                dist[s] = dist[t] + 1
                queue.append(s)
    return dist


# --- random Kripke structures (the strategies of test_ctl.py) -------------------------------


def box_sets(data: st.DataObject, box: int, count: st.SearchStrategy[int]) -> list[np.ndarray]:
    """Random subsets of the product box, as boolean arrays."""
    return [np.array(data.draw(st.lists(st.booleans(), min_size=box, max_size=box)), dtype=bool)
            for _ in range(data.draw(count))]


def on(space: StateSpace, box_mask: np.ndarray) -> np.ndarray:
    """A subset of the box (by code) over ``space``'s index space."""
    return box_mask[space.code_of(np.arange(space.size))] & space.stored()


def at(space: StateSpace, code: int) -> int:
    """Index of a stored code."""
    return int(space.index(np.array([code]))[0])


def on_states(ref: Explicit, mask: np.ndarray) -> set:
    return {m for m in ref.states if mask[ref.code(m)]}


def reference_eg(ref: Explicit, f: np.ndarray, fairness: list[np.ndarray]) -> tuple[set[int], set[int]]:
    eg, cycle = fair_eg_reference(ref.states, ref.succ.__getitem__, on_states(ref, f),
                                  [on_states(ref, c) for c in fairness])
    return codes_of(ref, eg), codes_of(ref, cycle)


def complete_and_truncated(data: st.DataObject) -> tuple[list[ComponentGraph], StateSpace, StateSpace]:
    """Random component graphs, their complete exploration and one cut at a random depth."""
    graphs = data.draw(systems(max_components=3, max_states=4))
    full = explore_graphs(graphs)
    return graphs, full, explore_graphs(graphs, max_depth=data.draw(st.integers(0, max(0, full.expanded_depth))))


@settings(max_examples=200, deadline=None)
@given(data=st.data())
def test_fair_eg_matches_definition(data: st.DataObject) -> None:
    graphs = data.draw(systems())
    space = explore_graphs(graphs)
    kripke = Kripke(space)
    ref = Explicit(graphs)
    box_f = box_sets(data, space.box, st.just(1))[0]
    box_fairness = box_sets(data, space.box, st.integers(0, 3))
    f, fairness = on(space, box_f), [on(space, c) for c in box_fairness]
    expected, cycles = reference_eg(ref, box_f, box_fairness)
    lower, upper = fair_eg(kripke, f, f, fairness)
    assert as_set(lower, space) == as_set(upper, space) == expected
    assert as_set(fair_scc_markings(kripke, f, fairness), space) == cycles
    box_g = box_sets(data, space.box, st.just(1))[0]
    g = on(space, box_g)
    af = fair_af(kripke, Result(g, g.copy()), fairness)
    not_g, _ = reference_eg(ref, ~box_g, box_fairness)
    assert as_set(af.lower, space) == as_set(af.upper, space) == codes_of(ref, ref.states) - not_g


@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_fair_eg_truncated_is_sound(data: st.DataObject) -> None:
    """Lower bounds are true on the complete run, upper bounds cover every true stored marking."""
    _, full, part = complete_and_truncated(data)
    complete, truncated = Kripke(full), Kripke(part)
    f, g = box_sets(data, full.box, st.just(2))
    fairness = box_sets(data, full.box, st.integers(0, 3))
    truth, _ = fair_eg(complete, on(full, f), on(full, f), [on(full, c) for c in fairness])
    lower, upper = fair_eg(truncated, on(part, f), on(part, f), [on(part, c) for c in fairness])
    assert not np.any(lower & ~upper) and not np.any(upper & ~truncated.stored)
    if part.complete:
        assert np.array_equal(lower, upper)
    stored = part.transfer(truncated.stored, full)
    lower, upper = part.transfer(lower, full), part.transfer(upper, full)  # into the complete run's index space
    assert not np.any(lower & ~truth)
    assert not np.any(truth & stored & ~upper)
    af_truth = fair_af(complete, Result(on(full, g), on(full, g)), [on(full, c) for c in fairness])
    af = fair_af(truncated, Result(on(part, g), on(part, g)), [on(part, c) for c in fairness])
    assert not np.any(af.lower & ~af.upper) and not np.any(af.upper & ~truncated.stored)
    af_lower, af_upper = part.transfer(af.lower, full), part.transfer(af.upper, full)
    assert not np.any(af_lower & ~af_truth.lower)
    assert not np.any(af_truth.lower & stored & ~af_upper)


@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_distance_to_is_breadth_first(data: st.DataObject) -> None:
    graphs, full, part = complete_and_truncated(data)
    kripke = Kripke(full)
    ref = Explicit(graphs)
    target = box_sets(data, full.box, st.just(1))[0]
    dist = distance_to(kripke, on(full, target))
    expected = bfs_distances(ref.states, ref.succ.__getitem__, on_states(ref, target))
    got = {ref.code(m): int(dist[at(full, ref.code(m))]) for m in ref.states}
    assert {c: d for c, d in got.items() if d != UNREACHED} == {ref.code(m): d for m, d in expected.items()}
    assert np.all(dist[~kripke.stored] == UNREACHED)
    # Truncated: a distance found inside the explored part is a real path, never shorter than the truth.
    short = part.transfer(distance_to(Kripke(part), on(part, target)), full, UNREACHED)
    known = short != UNREACHED
    assert np.all(short[known] >= dist[known])
    assert np.all(short[on(full, target) & part.transfer(part.stored(), full)] == 0)


def test_fair_cycle_must_meet_every_constraint() -> None:
    """0 <-> 1 and 1 -> 2 (dead): EG holds on the cycle only if the cycle meets the constraint."""
    space = explore_graphs([make_graph("c", [0, 0, 0], [{1}, {0, 2}, set()], [False] * 3, [0], [])])
    kripke = Kripke(space)
    everywhere = kripke.stored.copy()
    at = [np.arange(space.box) == i for i in range(3)]
    assert as_set(fair_eg(kripke, everywhere, everywhere, [])[0]) == {0, 1, 2}
    assert as_set(fair_eg(kripke, everywhere, everywhere, [at[0]])[0]) == {0, 1}
    assert as_set(fair_eg(kripke, everywhere, everywhere, [at[2]])[0]) == {0, 1, 2}  # the deadlock loops
    assert as_set(fair_eg(kripke, everywhere, everywhere, [at[0], at[2]])[0]) == set()
    no_dead = everywhere & ~at[2]
    assert as_set(fair_eg(kripke, no_dead, no_dead, [at[1]])[0]) == {0, 1}
    assert as_set(fair_af(kripke, Result(at[2], at[2]), [at[2]]).lower) == {0, 1, 2}
    assert as_set(fair_af(kripke, Result(at[2], at[2]), []).lower) == {2}


# --- skill fairness on real systems ---------------------------------------------------------


@cache
def mobile_manip() -> System:
    return load_system(ROOT / "skillsets" / "mobile_manip.toml")[0]


SYSTEMS = {"ovens": ovens, "mobile_manip": mobile_manip}
FAIR = PredictionOptions(PropertyOptions(af="fair"))


def idle_sets(ref: UnionGraph) -> list[set]:
    """Per skill of the system, the markings where it is idle."""
    out = []
    for c in ref.system.components:
        i = ref.names.index(c.name)
        for k in c.skillset.skills:
            bit = 1 << c.net.place_index(idle_place(k.name))
            out.append({m for m in ref.succ if m[i] & bit})
    return out


@pytest.mark.parametrize("name", SYSTEMS)
def test_forecast_fair_af_by_brute_force(name: str) -> None:
    """mu1 with fair AF is exactly not fair-EG phi, fairness = every skill idle infinitely often."""
    system = SYSTEMS[name]()
    fc = forecast(system, options=FAIR, full=True)
    ref = UnionGraph(system)
    code = {m: fc.space.code(ref.marking(m)) for m in ref.succ}
    assert fc.space.complete and set(code.values()) == as_set(fc.kripke.stored)
    idle = idle_sets(ref)
    assert [as_set(c & fc.kripke.stored) for c in skill_fairness(fc.kripke, system)] == \
        [{code[m] for m in s} for s in idle]
    for prop, risk in fc.risks.items():
        violating = {m for m in ref.succ if ref.violates(prop, m)}
        safe_forever, _ = fair_eg_reference(ref.succ, ref.succ.__getitem__, set(ref.succ) - violating, idle)
        expected = {code[m] for m in set(ref.succ) - safe_forever}
        assert risk.fair is not None and risk.mu1 is risk.fair
        assert as_set(risk.fair.lower) == as_set(risk.fair.upper) == expected, prop
        # Steps of a fair verdict: the fewest steps to a violation, along a real path.
        dist = bfs_distances(ref.succ, ref.succ.__getitem__, violating)
        for m in ref.succ:
            v = fc.verdict(prop, ref.marking(m))
            assert v.status == ("dangerous" if code[m] in expected else "safe")
            if v.status == "dangerous":
                assert v.steps == dist[m] == len(v.witness)
                current = {m}
                for label in v.witness:
                    current = {n for x in current for n, labels in ref.succ[x].items() if label in labels}
                assert current & violating


def test_fair_counts() -> None:
    """Fairness matters on the ovens (a running heat must end, and every outcome is Hot), not on mobile_manip."""
    fc = forecast(ovens(), options=FAIR, full=True)
    assert {p: (c["violating"], c["implicit_fair"], c["implicit_literal"], c["forced"])
            for p, c in fc.report()["properties"].items()} == {"hot": (14, 14, 10, 14), "both_hot": (4, 12, 12, 12)}
    # Literal AF lets oven2 `wait` forever while heat never ends; fair AF does not.
    net = ovens().component("oven").net
    heating = {"oven": net.marking_of({"temp.Warm", "i_heat", "e_wait"}), "oven2": net.initial}
    code = fc.space.code(heating)
    assert fc.risks["hot"].fair.lower[code] and not fc.risks["hot"].literal.upper[code]
    v = fc.verdict("hot", heating)
    assert (v.status, v.steps) == ("dangerous", 1)
    assert len(v.witness) == 1
    assert v.witness[0] in {"oven:heat.interrupt", "oven:heat.success.done", "oven:heat.failure.burnt"}
    mm_report = forecast(mobile_manip(), options=FAIR, full=True).report()["properties"]
    assert {p: (c["violating"], c["implicit_fair"], c["implicit_literal"], c["forced"])
            for p, c in mm_report.items()} == {"stowed_drive": (10, 0, 0, 2), "still_grasp": (6, 0, 0, 0)}
