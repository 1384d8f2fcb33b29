"""mu1 = Sat(AF not phi), step bounds, witnesses and truncated forecasts (docs/semantics.md §5, §6)."""

from __future__ import annotations

from collections import deque
from functools import cache
from itertools import product
from pathlib import Path

import numpy as np
import pytest

from skinet.lang.expr import Not
from skinet.lang.parser import parse_skillset
from skinet.net.semantics import stabilize, steps
from skinet.props.evaluate import holds
from skinet.props.formula import Temporal
from skinet.props.parser import parse_formula
from skinet.system.model import System, build_system
from skinet.verify.component import forget_component_graphs
from skinet.verify.ctl import Kripke, check
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.verify.predict import Forecast, forecast
from tests.corpus import require_corpus

LITERAL = PredictionOptions(PropertyOptions(af="literal"))


def literal_forecast(system: System, marking: dict[str, int] | None = None, **kwargs) -> Forecast:
    """mu1 with the paper's literal AF (these tests check it against brute force)."""
    return forecast(system, marking, options=LITERAL, **kwargs)

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT.parent / "shared" / "corpus"
PAPER = ROOT / "skillsets"

Combined = tuple[int, ...]

# CTL formulas over each system; ARM is the manipulator skill that moves to home.
FORMULAS = [
    "AF not (spot:i_go_to_waypoint and manipulator:i_ARM)",
    "EF spot:i_go_to_waypoint",
    "AG EF manipulator:e_ARM",
    "EG not spot:i_go_to_waypoint",
    "A[manipulator:e_ARM U spot:i_go_to_waypoint]",
    "E[not spot:i_go_to_waypoint U manipulator:i_ARM]",
    "AX EX true",
    "AF AG manipulator:e_ARM",
]
ARM = {"paper": "arm_RD_to_HP", "corpus": "arm_moving_to_HP"}
OVEN_FORMULAS = [
    "AF oven:Hot", "EF oven2:Hot", "AG EF oven:e_heat", "EG not oven:Hot", "A[oven:Cold U oven:i_heat]",
    "E[oven:e_heat U oven2:Hot]", "AX EX oven:Warm", "AF AG oven2:e_wait",
]


def _load(folder: Path, props: str) -> System:
    if not folder.exists():
        require_corpus()
    skillsets = [parse_skillset((folder / f).read_text(), str(folder / f)) for f in ("spot.rl", "manipulator.rl")]
    return build_system(folder.name, [(s, "") for s in skillsets], (folder / props).read_text())


@cache
def paper() -> System:
    return _load(PAPER, "spot_arm.props")


@cache
def corpus_pair() -> System:
    return _load(CORPUS, "spot_manipulator.props")


# Once `heat` starts, every outcome makes the oven Hot: implicit constraints with
# ranks above 0.  `wait` can cycle forever while Cold; `preheat` seeds a deadlock.
OVEN = """
skillset oven {
    resource { temp { state { Cold Warm Hot } initial Cold transition all } }
    event { preheat { guard temp == Cold effect temp -> Warm } }
    skill heat {
        precondition { cold: temp == Cold }
        start { temp -> Warm }
        interrupt { effect temp -> Hot }
        success done { effect temp -> Hot }
        failure burnt { effect temp -> Hot }
    }
    skill wait {
        precondition { cold: temp == Cold }
        success done {}
    }
}
"""


@cache
def ovens() -> System:
    skillsets = [parse_skillset(OVEN.replace("skillset oven", f"skillset {n}"), "<oven>") for n in ("oven", "oven2")]
    props = "hot = not oven:Hot\nboth_hot = not (oven:Hot and oven2:Hot)\n"
    return build_system("ovens", [(s, "") for s in skillsets], props)


SYSTEMS = {"paper": paper, "corpus": corpus_pair, "ovens": ovens}


class Explicit:
    """The union's stable graph, one combined marking at a time (no numpy, no product trick)."""

    def __init__(self, system: System):
        self.system = system
        comps = system.components
        self.names = [c.name for c in comps]
        initial = tuple(c.net.initial for c in comps)
        roots = list(product(*(sorted(stabilize(c.eventless, m)) for c, m in zip(comps, initial))))
        sources = set(roots)
        for i, c in enumerate(comps):
            for t, results in steps(c.net, initial[i]):
                if t.kind == "event":
                    sources |= {r[:i] + (m,) + r[i + 1:] for m in results for r in roots}
        self.succ: dict[Combined, dict[Combined, set[str]]] = {}
        queue = deque(sources)
        seen = set(sources)
        while queue:
            m = queue.popleft()
            out: dict[Combined, set[str]] = {}
            for i, c in enumerate(comps):
                for t, rs in steps(c.eventless, m[i]):
                    for r in rs:
                        out.setdefault(m[:i] + (r,) + m[i + 1:], set()).add(f"{c.name}:{t.name}")
            self.succ[m] = out or {m: set()}  # a deadlock is a sink
            for n in out:
                if n not in seen:
                    seen.add(n)
                    queue.append(n)

    def marking(self, m: Combined) -> dict[str, int]:
        return dict(zip(self.names, m))

    def violates(self, prop: str, m: Combined) -> bool:
        return not holds(self.system.property(prop).expr, self.marking(m), self.system.nets)

    def worst_steps(self, prop: str) -> dict[Combined, int]:
        """Markings from which every path violates ``prop``, with the longest such wait."""
        memo: dict[Combined, int | None] = {}
        active: set[Combined] = set()

        def worst(m: Combined) -> int | None:  # None: some path avoids the violation forever
            if m in memo:
                return memo[m]
            if self.violates(prop, m):
                memo[m] = 0
                return 0
            if m in active:
                return None  # a cycle without violation
            active.add(m)
            ws = [worst(n) for n in self.succ[m]]
            active.discard(m)
            memo[m] = None if any(w is None for w in ws) else 1 + max(ws)  # type: ignore[type-var]
            return memo[m]

        return {m: w for m in self.succ if (w := worst(m)) is not None}


@cache
def explicit(name: str) -> Explicit:
    return Explicit(SYSTEMS[name]())


def codes(fc: Forecast, ref: Explicit) -> dict[Combined, int]:
    out = {}
    for m in ref.succ:
        c = fc.space.code(ref.marking(m))
        assert c is not None
        out[m] = c
    return out


# --- figures ---------------------------------------------------------------------------------


def test_corpus_pair_mu1() -> None:
    report = literal_forecast(corpus_pair()).report()
    assert (report["complete"], report["markings"], report["edges"], report["deadlocks"]) == (True, 1628, 7638, 0)
    assert report["properties"] == {
        "action_guard": {"violating": 500, "dangerous": 500, "undecided": 0, "safe": 1128,
                         "implicit_literal": 0, "undecided_literal": 0},
        "safety_guard": {"violating": 36, "dangerous": 36, "undecided": 0, "safe": 1592,
                         "implicit_literal": 0, "undecided_literal": 0},
    }


def test_paper_mu1_stable_across_runs() -> None:
    system = paper()
    runs = [literal_forecast(system) for _ in range(2)]
    for c in system.components:
        forget_component_graphs(c.eventless)
    runs.append(literal_forecast(system))
    reports = [{k: v for k, v in r.report().items() if k != "elapsed"} for r in runs]
    assert reports[0] == reports[1] == reports[2]
    assert reports[0]["complete"] and reports[0]["deadlocks"] == 0
    for prop in runs[0].risks:
        for r in runs[1:]:
            assert np.array_equal(r.risks[prop].mu1.lower, runs[0].risks[prop].mu1.lower)
            assert np.array_equal(r.risks[prop].mu1.rank, runs[0].risks[prop].mu1.rank)


@pytest.mark.parametrize("name", SYSTEMS)
def test_mu1_and_steps_by_brute_force(name: str) -> None:
    """mu1 is exactly the set where every path violates; ``steps`` is the longest wait."""
    fc = literal_forecast(SYSTEMS[name]())
    ref = explicit(name)
    code = codes(fc, ref)
    assert fc.space.markings == len(ref.succ)
    for prop, risk in fc.risks.items():
        worst = ref.worst_steps(prop)
        assert {code[m] for m in worst} == set(np.flatnonzero(risk.mu1.lower).tolist())
        assert {code[m] for m in ref.succ if ref.violates(prop, m)} == set(np.flatnonzero(risk.violating).tolist())
        for m, w in worst.items():
            v = fc.verdict(prop, ref.marking(m))
            assert v.status == "dangerous" and v.steps == w
        for m in set(ref.succ) - set(worst):
            assert fc.verdict(prop, ref.marking(m)).status == "safe"


@pytest.mark.parametrize("name", SYSTEMS)
def test_witnesses_are_real_paths(name: str) -> None:
    """A witness replays on the nets, stays safe until its last step, which violates; it is no longer than ``steps``."""
    fc = literal_forecast(SYSTEMS[name]())
    ref = explicit(name)
    for prop, risk in fc.risks.items():
        for m in ref.worst_steps(prop):
            v = fc.verdict(prop, ref.marking(m))
            assert v.steps is not None and len(v.witness) <= v.steps
            current = {m}
            for i, label in enumerate(v.witness):
                assert all(not ref.violates(prop, x) for x in current)
                current = {n for x in current for n, labels in ref.succ[x].items() if label in labels}
                assert current, (m, v.witness[: i + 1])
            assert any(ref.violates(prop, x) for x in current)
            assert v.witness or ref.violates(prop, m)


def test_ovens_have_implicit_constraints() -> None:
    """The systems above have none (mu1 = violating); this one exercises ranks and witnesses."""
    fc = literal_forecast(ovens())
    risk = fc.risks["hot"]
    implicit = risk.mu1.lower & ~risk.violating
    assert implicit.any() and risk.mu1.rank[implicit].max() >= 2
    assert fc.report()["deadlocks"] > 0
    shorter = [c for c in np.flatnonzero(implicit) if len(fc.witness("hot", int(c))) < risk.mu1.rank[c]]
    assert shorter  # the witness is one path, not the longest one: steps is a bound
    net = ovens().component("oven").net
    heating = net.marking_of({"temp.Warm", "i_heat", "e_wait"})
    stuck = net.marking_of({"temp.Warm", "e_heat", "e_wait"})  # oven2 preheated: dead
    v = fc.verdict("hot", {"oven": heating, "oven2": stuck})
    assert (v.status, v.steps, len(v.witness)) == ("dangerous", 1, 1)
    assert v.witness[0] in {"oven:heat.interrupt", "oven:heat.success.done", "oven:heat.failure.burnt"}
    # No fairness: while oven2 can `wait` forever, oven may never be scheduled.
    assert fc.verdict("hot", {"oven": heating, "oven2": ovens().component("oven2").net.initial}).status == "safe"


def test_unknown_marking_is_undecided() -> None:
    fc = literal_forecast(paper(), compositional=False)
    marking = dict(paper().initial_marking())
    marking["spot"] = 0  # no token anywhere: never reached
    assert fc.verdict("action_guard", marking).status == "undecided"


# --- truncation ------------------------------------------------------------------------------


def test_zero_budget_report_is_honest() -> None:
    system = corpus_pair()
    fc = literal_forecast(system, budget=0.0)
    report = fc.report()
    sources = fc.space.layers[0]
    assert report["complete"] is False and report["timeout_reached"] is True
    assert (report["depth"], report["markings"], report["edges"]) == (-1, sources, 0)
    assert (report["frontier"], report["deadlocks"]) == (sources, 0)
    for prop, counts in report["properties"].items():
        violating = int(np.count_nonzero(fc.risks[prop].violating))
        # A source that violates already is proven; nothing else is, and nothing is safe.
        assert counts == {"violating": violating, "dangerous": violating, "undecided": sources - violating, "safe": 0,
                          "implicit_literal": 0, "undecided_literal": sources - violating}
    full = literal_forecast(system)
    for c in np.flatnonzero(fc.kripke.stored):
        marking = fc.space.marking(int(c))
        for prop in fc.risks:
            assert fc.verdict(prop, marking).status in ("dangerous", "undecided")
            if fc.verdict(prop, marking).status == "dangerous":
                assert full.verdict(prop, marking).status == "dangerous"


@pytest.mark.parametrize("name", SYSTEMS)
def test_truncated_forecast_is_sound(name: str) -> None:
    system = SYSTEMS[name]()
    full = literal_forecast(system)
    kripke_full = full.kripke
    skillsets = {c.name: c.skillset for c in system.components}
    texts = OVEN_FORMULAS if name == "ovens" else [f.replace("ARM", ARM[name]) for f in FORMULAS]
    formulas = [parse_formula(f, skillsets) for f in texts]
    formulas += [Temporal("AF", Not(p.expr)) for p in system.properties]
    for max_depth in range(full.space.expanded_depth + 1):
        part = literal_forecast(system, max_depth=max_depth)
        kripke, space = part.kripke, part.space
        assert not part.space.complete
        assert not np.any(kripke.deadlock & kripke.frontier)

        def lift(values: np.ndarray, fill: object = False) -> np.ndarray:  # into the full run's index space
            return space.transfer(values, full.space, fill)

        stored = lift(kripke.stored)
        assert np.array_equal(lift(kripke.deadlock), kripke_full.deadlock & lift(kripke.expanded))
        for f in formulas:
            truth, r = check(kripke_full, f), check(kripke, f)
            assert not np.any(r.lower & ~r.upper)
            assert not np.any(lift(r.lower) & ~truth.lower), (max_depth, f)
            assert not np.any(stored & truth.lower & ~lift(r.upper)), (max_depth, f)
        for prop, risk in part.risks.items():
            proven = lift(risk.mu1.lower)
            # mu1's argument is a state formula: a proven rank is the exact one.
            assert np.array_equal(lift(risk.mu1.rank, 0)[proven], full.risks[prop].mu1.rank[proven])
            for c in np.flatnonzero(kripke.stored):
                marking = part.space.marking(int(c))
                got, truth = part.verdict(prop, marking), full.verdict(prop, marking)
                assert got.status in (truth.status, "undecided"), (max_depth, prop, marking)
                if got.status == "dangerous":
                    assert got.steps == truth.steps
    assert literal_forecast(system, max_depth=full.space.expanded_depth + 1).space.complete


def test_truncated_witness_stays_inside() -> None:
    """On a truncated run a witness only uses explored markings and still ends in a violation."""
    system = corpus_pair()
    part = literal_forecast(system, max_depth=4)
    for prop, risk in part.risks.items():
        for c in np.flatnonzero(risk.mu1.lower)[:200]:
            code = int(c)
            path = [code]
            while risk.mu1.rank[path[-1]] > 0:
                path.append(min(part.space.successors(path[-1]), key=lambda s: risk.mu1.rank[s[0]])[0])
            assert all(part.kripke.stored[p] for p in path) and risk.violating[path[-1]]
            assert len(path) - 1 == len(part.witness(prop, code)) <= risk.mu1.rank[code]


def test_kripke_of_forecast_matches_fresh_kripke() -> None:
    fc = literal_forecast(paper())
    k = Kripke(fc.space)
    assert np.array_equal(k.deadlock, fc.kripke.deadlock) and np.array_equal(k.outdeg, fc.kripke.outdeg)
