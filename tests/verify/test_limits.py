"""The budget and the memory limit bound the whole answer; nothing is refused (docs/semantics.md §6.1).

Soundness at every limit: whatever stopped the work (depth, memory, the
deadline inside the exploration or inside any fixpoint), what the truncated
answer proves the complete one proves too, and what it refutes the complete
one refutes.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from skinet.lang.expr import Not
from skinet.props.formula import Temporal
from skinet.props.parser import parse_formula
from skinet.system.model import System
from skinet.verify.algorithm1 import analyse
from skinet.verify.ctl import Kripke, Result, check
from skinet.verify.component import forget_component_graphs
from skinet.verify.explore import Deadline, explore, layer_counts, resident_bytes
from skinet.verify import symbolic
from skinet.verify.predict import forecast
from tests.verify.test_compositional import copies as corpus_copies

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT.parent / "shared" / "corpus"


def copies(n_spot: int, n_arm: int) -> System:
    """``n_spot`` copies of the corpus Spot and ``n_arm`` of its arm."""
    return corpus_copies(CORPUS, "spot_manipulator.props", n_spot, n_arm)


@cache
def pair_and_arm() -> System:
    return copies(1, 2)


FORMULAS = [
    "AF not (spot:i_go_to_waypoint and manipulator:i_arm_moving_to_HP)",
    "EF manipulator2:i_arm_moving_to_HP",
    "AG EF manipulator:e_arm_moving_to_HP",
    "EG not spot:i_go_to_waypoint",
    "A[manipulator:e_arm_moving_to_HP U spot:i_go_to_waypoint]",
    "AX EX true",
]


class CountingDeadline(Deadline):
    """Expires at its ``n``-th check: cuts the work at every possible place in turn."""

    def __init__(self, n: int) -> None:
        super().__init__(0.0)
        self.n = n

    def expired(self) -> bool:
        self.n -= 1
        self.hit = self.hit or self.n < 0
        return self.hit


def assert_sound(full: Kripke, part: Kripke, formulas: list) -> None:
    fs, ps = full.space, part.space
    for f in formulas:
        truth, got = check(full, f), check(part, f)
        assert np.array_equal(truth.lower, truth.upper)
        assert not np.any(got.lower & ~got.upper), f
        lower, upper = ps.transfer(got.lower, fs), ps.transfer(got.upper, fs)
        stored = ps.transfer(part.stored, fs)
        assert not np.any(lower & ~truth.lower), f  # proven: true
        assert not np.any(stored & truth.lower & ~upper), f  # refuted: false


def formulas(system: System) -> list:
    names = {c.name: c.skillset for c in system.components}
    return [parse_formula(f, names) for f in FORMULAS] + [Temporal("AF", Not(p.expr)) for p in system.properties]


def test_layer_counts_match_the_enumeration() -> None:
    for seeds in (False, True):
        space = explore(pair_and_arm(), event_seeds=seeds, memory_limit=None)
        assert space.complete and sum(space.layers) == space.markings
        assert space.layers == np.bincount(space.depth[space.depth >= 0]).tolist()
        assert layer_counts(space.components) == space.layers


@pytest.mark.parametrize("seeds", [False, True])
def test_deadline_inside_fixpoints_is_sound(seeds: bool) -> None:
    """The deadline expiring at any check of any fixpoint leaves a sound three-valued answer."""
    system = pair_and_arm()
    fs = formulas(system)
    full = Kripke(explore(system, event_seeds=seeds))
    checks = 0
    while True:
        space = explore(system, event_seeds=seeds)
        space.deadline = CountingDeadline(checks)
        part = Kripke(space)
        assert_sound(full, part, fs)
        if not part.cut:
            break  # every fixpoint of every formula ran to the end
        assert part.truncated_by == "budget"
        checks += 2
    assert checks > 20  # the cuts did happen inside the fixpoints


@pytest.mark.parametrize("seeds", [False, True])
def test_deadline_inside_the_exploration_is_sound(seeds: bool) -> None:
    system = pair_and_arm()
    full = Kripke(explore(system, event_seeds=seeds))
    for checks in range(0, 40, 3):
        space = explore(system, event_seeds=seeds, deadline=CountingDeadline(checks))
        assert space.truncated_by == "budget" and not space.complete
        assert_sound(full, Kripke(space), formulas(system))


def test_memory_limit_truncates_soundly() -> None:
    system = pair_and_arm()
    full = Kripke(explore(system, memory_limit=None))
    seen = set()
    for extra in (0, 50_000, 200_000, 1_000_000, 4_000_000):
        space = explore(system, memory_limit=resident_bytes() + extra, properties=len(system.properties))
        assert space.truncated_by == ("memory" if not space.complete else None)
        seen.add(space.markings)
        assert_sound(full, Kripke(space), formulas(system))
    assert len(seen) >= 3 and max(seen) == full.space.markings


def test_truncated_verdicts_never_contradict() -> None:
    """Algorithm 1 on a truncated forecast: unknown where undecided, never safe instead of implicit."""
    system = pair_and_arm()
    marking = system.initial_marking()
    truth = analyse(system, marking, forecast(system, marking))
    exact = {(u.skillset, u.transition, u.property): u.constraint for u in truth.unsafe}
    for limit in (0, 20_000, 100_000, 400_000, 8_000_000):
        fc = forecast(system, marking, memory_limit=resident_bytes() + limit)
        got = {(u.skillset, u.transition, u.property): u.constraint for u in analyse(system, marking, fc).unsafe}
        for key, constraint in exact.items():
            assert got.get(key) in (constraint, "unknown"), key
        assert all(c == "unknown" for key, c in got.items() if key not in exact)
    assert got == exact  # the last limit leaves room for the whole answer


@pytest.mark.parametrize(("n_spot", "n_arm", "seeds"), [(3, 3, True), (4, 4, False), (4, 4, True)])
def test_formerly_refused_systems_are_answered(n_spot: int, n_arm: int, seeds: bool) -> None:
    """3 + 3 with seeds and 4 + 4 were refused (product box over the cap); now: a truncated answer in time."""
    system = copies(n_spot, n_arm)
    started = time.perf_counter()
    fc = forecast(system, budget=1.0, event_seeds=seeds)
    assert time.perf_counter() - started < 3.0  # the budget, plus parsing the components, on a loaded machine
    report = fc.report()
    assert not report["complete"] and report["truncated_by"] in ("budget", "memory")
    assert report["markings"] > 0 and report["markings"] == sum(fc.space.layers)
    # Fair AF (the default) on a box this big is computed by BDD, unless the half budget the exploration
    # may take was gone before it (a loaded machine): then it is undecided, never guessed.
    if fc.symbolic_fair is None:
        assert not symbolic.available() or report["truncated_by"] == "budget"
    for counts in report["properties"].values():
        assert counts["dangerous"] + counts["undecided"] + counts["safe"] == report["markings"]
        if fc.symbolic_fair is None:
            assert counts["undecided"] > 0
        else:  # exact at every stored marking when its fixpoint ended in the budget, else nothing is decided
            assert counts["undecided"] in (0, report["markings"])
    analysis = analyse(system, system.initial_marking(), fc)
    assert {u.constraint for u in analysis.unsafe} <= {"explicit", "implicit", "unknown"}


MEMORY_SCRIPT = """
import json, sys
sys.path.insert(0, {root!r})
from tests.verify.test_limits import copies
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.verify.explore import peak_resident_bytes, resident_bytes
from skinet.verify.predict import forecast
start = resident_bytes()
fc = forecast(copies(3, 3), event_seeds=False, memory_limit={limit},
              options=PredictionOptions(PropertyOptions(af={af!r})))
print(json.dumps({{"peak": peak_resident_bytes(), "start": start, **fc.report()}}))
"""


@pytest.mark.parametrize("af", ["literal", "fair"])
@pytest.mark.parametrize("limit_mib", [150, 300])
def test_memory_limit_bounds_the_peak(limit_mib: int, af: str) -> None:
    """3 + 3 without seeds is a full box of 122 023 936 markings: a fresh process stays under the limit."""
    copies(1, 1)  # skips without the corpus
    script = MEMORY_SCRIPT.format(root=str(ROOT), limit=limit_mib << 20, af=af)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, check=True)
    report = json.loads(out.stdout)
    assert report["truncated_by"] == "memory" and not report["complete"]
    assert report["peak"] <= limit_mib << 20, report
    assert report["markings"] > 100 * limit_mib  # not a trivial answer either


def test_result_arrays_are_shared_when_exact() -> None:
    """On a complete run lower and upper are one array: half the memory of mu1."""
    system = pair_and_arm()
    k = Kripke(explore(system))
    r: Result = check(k, Temporal("AF", Not(system.properties[0].expr)))
    assert r.lower is r.upper and r.rank is not None and r.rank.dtype == np.uint8


def test_budget_expiring_inside_a_component_leaves_everything_unknown() -> None:
    """The budget also bounds exploring each component: cut there, only the live marking is stored, unexpanded."""
    system = copies(1, 2)  # fresh: no compositional verdict memoised by another test
    for c in system.components:
        forget_component_graphs(c.eventless)
    fc = forecast(system, budget=0.0)
    report = fc.report()
    assert (report["markings"], report["frontier"], report["deadlocks"]) == (1, 1, 0)
    assert report["truncated_by"] == "budget" and not report["complete"]
    analysis = analyse(system, system.initial_marking(), fc)
    exact = analyse(system, system.initial_marking(), forecast(system))
    assert {(u.skillset, u.transition, u.property) for u in analysis.unsafe} >= {
        (u.skillset, u.transition, u.property) for u in exact.unsafe}
    assert {u.constraint for u in analysis.unsafe} <= {"explicit", "forced", "unknown"}
    assert "unknown" in {u.constraint for u in analysis.unsafe}
