"""Compositional verdicts equal the global fixpoints wherever both answer (docs/semantics.md §6.2, §6.4)."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest

from skinet.lang.parser import parse_skillset
from skinet.net.semantics import steps
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.system.model import System, build_system
from skinet.verify.compositional import CompositionalOracle, one_step
from skinet.verify.explore import Deadline
from skinet.verify.predict import forecast
from tests.corpus import require_corpus

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT.parent / "shared" / "corpus"


def copies(folder: Path, props: str, n_spot: int, n_arm: int) -> System:
    if not folder.exists():
        require_corpus()
    spot, arm = (folder / "spot.rl").read_text(), (folder / "manipulator.rl").read_text()
    out = []
    for k in range(1, n_spot + 1):
        name = "spot" if k == 1 else f"spot{k}"
        out.append(parse_skillset(re.sub(r"skillset\s+spot\b", f"skillset {name}", spot, count=1), name))
    for k in range(1, n_arm + 1):
        name = "manipulator" if k == 1 else f"manipulator{k}"
        out.append(parse_skillset(re.sub(r"skillset\s+manipulator\b", f"skillset {name}", arm, count=1), name))
    return build_system(f"{n_spot}+{n_arm}", [(s, "") for s in out], (folder / props).read_text())


SYSTEMS = {
    "paper": lambda: copies(ROOT / "skillsets", "spot_arm.props", 1, 1),
    "corpus": lambda: copies(CORPUS, "spot_manipulator.props", 1, 1),
    "corpus 1+2": lambda: copies(CORPUS, "spot_manipulator.props", 1, 2),
    "ovens": lambda: __import__("test_predict").ovens(),
}


@pytest.mark.parametrize("af", ["literal", "fair"])
@pytest.mark.parametrize("name", SYSTEMS)
def test_equals_global_fixpoints(name: str, af: str) -> None:
    system = SYSTEMS[name]()
    fc = forecast(system, options=PredictionOptions(PropertyOptions(af=af)), memory_limit=None)
    assert fc.space.complete
    oracle = CompositionalOracle(system)
    stored = np.flatnonzero(fc.kripke.stored)
    sample = stored if stored.size <= 400 else np.random.default_rng(7).choice(stored, 400, replace=False)
    kinds = set()
    for i in sample:
        marking = fc.space.marking(int(i))
        for p in system.properties:
            want, got = fc.verdict(p.name, marking), oracle.verdict(p, marking, af)
            assert got.status == want.status, (name, af, p.name, marking)
            kinds.add(got.status)
            if got.status == "dangerous":
                assert got.steps == want.steps  # literal: the bound; fair: the fewest
    assert "safe" in kinds


def test_successors_of_a_huge_system_are_decided() -> None:
    """Four Spots and four arms (about 7.7e12 markings with seeds): every successor decided.

    Timed in benchmarks/bench_big.py (b); here only a loose bound (2 shared cores).
    """
    system = copies(CORPUS, "spot_manipulator.props", 4, 4)
    oracle = CompositionalOracle(system)
    start = system.initial_marking()
    started = time.perf_counter()
    deadline = Deadline.after(10.0)
    verdicts = [oracle.verdict(p, after, af, deadline).status
                for after in one_step(system, start) for p in system.properties for af in ("literal", "fair")]
    assert time.perf_counter() - started < 10.0
    assert verdicts and "undecided" not in verdicts


def test_algorithm1_on_a_huge_system_has_no_unknown() -> None:
    """The predictor's answer on 4 + 4: exploration truncated, yet every successor decided.

    Truncated by depth, not by a time budget: on a loaded machine a budget leaves the compositional
    verdicts no time, and then `unknown` is the right answer (what a budget promises is tested in
    tests/verify/test_limits.py)."""
    from skinet.verify.algorithm1 import analyse

    system = copies(CORPUS, "spot_manipulator.props", 4, 4)
    marking = system.initial_marking()
    marking["spot"] = next(m for t, results in steps(system.component("spot").net, marking["spot"])
                           if t.name == "init_power.start" for m in results)
    fc = forecast(system, marking, max_depth=4)
    assert not fc.report()["complete"] and fc.report()["markings"] == 107889
    analysis = analyse(system, marking, fc)
    assert analysis.unsafe and all(u.constraint != "unknown" for u in analysis.unsafe)
