"""Fair AF by decision diagrams (skinet.verify.symbolic): the definition, the explicit fixpoints, forecast."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skinet.system.load import load_system
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.system.model import System
from skinet.verify import symbolic
from skinet.verify.explore import Deadline, StateSpace, explore_graphs
from skinet.verify.predict import forecast
from skinet.verify.symbolic import SymbolicProduct
from tests.verify.test_ctl import Explicit, as_set, codes_of, systems
from tests.verify.test_fair import bfs_distances, box_sets, fair_eg_reference, mobile_manip, on_states
from tests.verify.test_limits import copies
from tests.verify.test_predict import ovens

pytestmark = pytest.mark.skipif(not symbolic.available(), reason="dd.cudd is missing (dd's x86_64 wheels carry it)")

ROOT = Path(__file__).resolve().parents[2]
FAIR = PredictionOptions(PropertyOptions(af="fair"))


def from_box(product: SymbolicProduct, space: StateSpace, mask: np.ndarray) -> symbolic.Function:
    """A subset of the box (by code) as a BDD."""
    f = product.bdd.false
    for code in np.flatnonzero(mask):
        f |= product.marking([(int(code) // s) % n for s, n in zip(space.strides, space.shape)])
    return f


@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_fair_eg_matches_definition(data: st.DataObject) -> None:
    """Complete and truncated spaces (box and stored codes): exact at every stored marking."""
    graphs = data.draw(systems(max_components=3, max_states=4))
    full = explore_graphs(graphs)
    part = explore_graphs(graphs, max_depth=data.draw(st.integers(0, max(0, full.expanded_depth))))
    ref = Explicit(graphs)
    box_f = box_sets(data, full.box, st.just(1))[0]
    box_fairness = box_sets(data, full.box, st.integers(0, 3))
    product = SymbolicProduct(graphs)
    eg = product.fair_eg(from_box(product, full, box_f), [from_box(product, full, c) for c in box_fairness],
                         Deadline())
    expected, _ = fair_eg_reference(ref.states, ref.succ.__getitem__, on_states(ref, box_f),
                                    [on_states(ref, c) for c in box_fairness])
    for space in (full, part):
        got = product.mask(eg, space) & space.stored()
        assert as_set(got, space) == codes_of(ref, expected) & as_set(space.stored(), space)


@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_shortest_path_is_breadth_first(data: st.DataObject) -> None:
    graphs = data.draw(systems(max_components=3, max_states=4))
    space = explore_graphs(graphs)
    ref = Explicit(graphs)
    target = box_sets(data, space.box, st.just(1))[0]
    product = SymbolicProduct(graphs)
    goal = from_box(product, space, target)
    dist = bfs_distances(ref.states, ref.succ.__getitem__, on_states(ref, target))
    for m in ref.states:
        path = product.shortest_path(list(m), goal, Deadline())
        if m not in dist:
            assert path is None
            continue
        assert path is not None and len(path) == dist[m]
        at = list(m)
        for i, a, b in path:
            assert at[i] == a and b in graphs[i].succ[a]
            at[i] = b
        assert target[ref.code(tuple(at))]


def test_deadline_passed_is_undecided() -> None:
    graphs = [g for g in forecast(copies(1, 2)).space.components]
    product = SymbolicProduct(graphs)
    phi = product.formula(copies(1, 2).properties[0].expr)
    assert product.fair_eg(phi, product.skill_fairness(copies(1, 2)), Deadline(0.0)) is None
    assert product.shortest_path([0] * len(graphs), ~phi, Deadline(0.0)) in (None, [])


@cache
def spot_arm() -> System:
    return load_system(ROOT / "skillsets" / "spot_arm.toml")[0]


SYSTEMS = {"paper": spot_arm, "ovens": ovens, "mobile_manip": mobile_manip, "corpus 1+2": lambda: copies(1, 2)}


@pytest.mark.parametrize("name", SYSTEMS)
def test_forecast_symbolic_equals_explicit(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Same fair mu1 at every marking, same steps; a witness is a shortest path to a violation."""
    system = SYSTEMS[name]()
    explicit = forecast(system, options=FAIR)
    monkeypatch.setattr(symbolic, "SYMBOLIC_FROM", 0)
    sym = forecast(system, options=FAIR)
    assert sym.symbolic_fair is not None and explicit.symbolic_fair is None
    assert sym.report() == {**explicit.report(), "elapsed": sym.report()["elapsed"]}
    for prop in explicit.risks:
        e, s = explicit.risks[prop].fair, sym.risks[prop].fair
        assert e is not None and s is not None
        assert np.array_equal(e.lower, s.lower) and np.array_equal(e.upper, s.upper)
        for code in np.flatnonzero(e.lower)[:: max(1, int(np.count_nonzero(e.lower)) // 40)]:
            marking = explicit.space.marking(int(code))
            want, got = explicit.verdict(prop, marking), sym.verdict(prop, marking)
            assert (got.status, got.steps) == (want.status, want.steps)
            assert len(got.witness) == len(want.witness)


def test_truncated_exploration_gets_exact_fair_verdicts(monkeypatch: pytest.MonkeyPatch) -> None:
    """Explicit fair AF leaves the frontier undecided; the BDD decides every stored marking as the complete run."""
    system = copies(1, 2)
    complete = forecast(system, options=FAIR)
    cut = forecast(system, options=FAIR, max_depth=2)
    monkeypatch.setattr(symbolic, "SYMBOLIC_FROM", 0)
    sym = forecast(system, options=FAIR, max_depth=2)
    assert not cut.space.complete and sym.space.markings == cut.space.markings
    for prop, risk in complete.risks.items():
        stored = sym.kripke.stored
        want = complete.space.transfer(risk.fair.lower, sym.space) & stored
        got = sym.risks[prop].fair
        assert np.array_equal(got.lower, want) and np.array_equal(got.upper, want)
        explicit = cut.risks[prop].fair
        assert np.count_nonzero(explicit.upper & ~explicit.lower) > 0  # what the BDD decides in addition


def test_two_and_two_counts(monkeypatch: pytest.MonkeyPatch) -> None:
    """2 spots + 2 arms without seeds: 246 016 markings, the same fair mu1 counts both ways."""
    system = copies(2, 2)
    explicit = forecast(system, options=FAIR, event_seeds=False).report()
    monkeypatch.setattr(symbolic, "SYMBOLIC_FROM", 0)
    sym = forecast(system, options=FAIR, event_seeds=False).report()
    assert sym["markings"] == explicit["markings"] == 246_016 and sym["complete"]
    assert {p: c["dangerous"] for p, c in sym["properties"].items()} == \
        {p: c["dangerous"] for p, c in explicit["properties"].items()} == \
        {"action_guard": 99_200, "safety_guard": 5_952}
