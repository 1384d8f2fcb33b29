"""Strongly connected components in Python for small graphs, scipy for large ones (skinet/verify/scc.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from skinet.system.load import load_system
from skinet.verify import scc
from skinet.lang.expr import Not
from skinet.verify.ctl import check
from skinet.verify.fair import fair_scc_markings, skill_fairness
from skinet.verify.predict import forecast
from tests.verify.test_limits import pair_and_arm

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def python_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(scc, "scipy_loaded", lambda: False)
    monkeypatch.setattr(scc, "SMALL_GRAPH", 10**12)


@pytest.fixture
def scipy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(scc, "SMALL_GRAPH", -1)


def _csr(n: int, edges: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    succ: list[list[int]] = [[] for _ in range(n)]
    for a, b in edges:
        succ[a].append(b)
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum([len(s) for s in succ], out=indptr[1:])
    return indptr, np.array([b for s in succ for b in s], dtype=np.int32)


def _partition(labels: np.ndarray) -> set[frozenset[int]]:
    groups: dict[int, set[int]] = {}
    for v, label in enumerate(labels.tolist()):
        groups.setdefault(label, set()).add(v)
    return {frozenset(g) for g in groups.values()}


def _both(monkeypatch: pytest.MonkeyPatch, indptr: np.ndarray, indices: np.ndarray) -> tuple[tuple, tuple]:
    with monkeypatch.context() as m:
        m.setattr(scc, "scipy_loaded", lambda: False)
        m.setattr(scc, "SMALL_GRAPH", 10**12)
        ours = scc.strong_components(indptr, indices)
    with monkeypatch.context() as m:
        m.setattr(scc, "SMALL_GRAPH", -1)
        theirs = scc.strong_components(indptr, indices)
    return ours, theirs


def test_known_components(python_path: None) -> None:
    # 0 <-> 1 -> 2 -> 3 -> 2, 4 alone with a self-loop, 5 alone
    indptr, indices = _csr(6, [(0, 1), (1, 0), (1, 2), (2, 3), (3, 2), (4, 4)])
    count, labels = scc.strong_components(indptr, indices)
    assert count == 4
    assert _partition(labels) == {frozenset({0, 1}), frozenset({2, 3}), frozenset({4}), frozenset({5})}
    assert sorted(set(labels.tolist())) == [0, 1, 2, 3]
    assert scc.strong_components(np.zeros(1, dtype=np.int32), np.zeros(0, dtype=np.int32))[0] == 0


def test_deep_chain_needs_no_recursion(python_path: None) -> None:
    n = 50_000  # far beyond Python's recursion limit
    indptr, indices = _csr(n, [(i, i + 1) for i in range(n - 1)] + [(n - 1, 0)])
    count, labels = scc.strong_components(indptr, indices)
    assert count == 1 and labels.shape == (n,)
    indptr, indices = _csr(n, [(i, i + 1) for i in range(n - 1)])
    assert scc.strong_components(indptr, indices)[0] == n


def _random_edges(seed: int) -> tuple[int, list[tuple[int, int]]]:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    m = int(rng.integers(0, 3 * n))
    return n, list(zip(rng.integers(0, n, m).tolist(), rng.integers(0, n, m).tolist()))


def _reference(n: int, edges: list[tuple[int, int]]) -> set[frozenset[int]]:
    """SCCs by definition: v and w together when each reaches the other."""
    succ: list[set[int]] = [set() for _ in range(n)]
    for a, b in edges:
        succ[a].add(b)
    reach = []
    for v in range(n):
        seen, todo = {v}, [v]
        while todo:
            for w in succ[todo.pop()] - seen:
                seen.add(w)
                todo.append(w)
        reach.append(seen)
    return {frozenset(w for w in reach[v] if v in reach[w]) for v in range(n)}


@pytest.mark.parametrize("seed", range(20))
def test_python_and_scipy_agree(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    n, edges = _random_edges(seed)
    edges = list(dict.fromkeys(edges))  # no repeated edge (strong_components' precondition)
    (c1, l1), (c2, l2) = _both(monkeypatch, *_csr(n, edges))
    assert c1 == c2 == len(_reference(n, edges))
    assert _partition(l1) == _partition(l2) == _reference(n, edges)


def test_repeated_edges(monkeypatch: pytest.MonkeyPatch) -> None:
    n, edges = _random_edges(5)
    assert len(set(edges)) < len(edges)
    expected = _reference(n, edges)
    assert len(expected) == 39
    (c1, l1), (c2, l2) = _both(monkeypatch, *_csr(n, edges))
    assert c1 == 39 and _partition(l1) == expected  # Tarjan does not mind repeats
    assert c2 == 57  # scipy 1.17 on a CSR with repeated entries: wrong, hence the precondition
    succ: list[list[int]] = [[] for _ in range(n)]
    for a, b in edges:
        succ[a].append(b)
    for small in (10**12, -1):  # the list form removes repeats on both paths
        with monkeypatch.context() as m:
            m.setattr(scc, "scipy_loaded", lambda: False)
            m.setattr(scc, "SMALL_GRAPH", small)
            count, labels = scc.strong_components_of_lists(succ)
        assert count == 39 and _partition(labels) == expected


@pytest.mark.parametrize("name", ["paper", "pair_and_arm"])
def test_forecasts_agree_on_both_paths(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0] if name == "paper" else pair_and_arm()
    reports = []
    for small in (10**12, -1):
        with monkeypatch.context() as m:
            m.setattr(scc, "scipy_loaded", lambda: False)
            m.setattr(scc, "SMALL_GRAPH", small)
            fc = forecast(system, budget=None, full=True)
            report = fc.report()
            report.pop("elapsed")
            fairness = skill_fairness(fc.kripke, system)
            fair = []  # markings on fair cycles inside each property and inside random subsets
            rng = np.random.default_rng(7)
            insides = [fc.kripke.expanded & ~check(fc.kripke, Not(prop.expr)).lower for prop in system.properties]
            insides += [fc.kripke.expanded & (rng.random(fc.kripke.space.size) < 0.8) for _ in range(5)]
            for keeps in insides:
                found = fair_scc_markings(fc.kripke, keeps, fairness)
                assert found is not None
                fair.append((int(keeps.sum()), found.tolist()))
            reports.append((report, fair,
                            {p: (r.fair.lower.tolist(), r.fair.upper.tolist()) for p, r in fc.risks.items()}))
    assert reports[0] == reports[1]
    assert any(0 < sum(found) < keeps for keeps, found in reports[0][1])  # some on fair cycles, not all


def _imports_scipy(system_expr: str) -> bool:
    code = ("import sys; from skinet.verify.predict import forecast; "
            f"{system_expr}; forecast(system, budget=None); print('scipy.sparse.csgraph' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip() == "True"


@pytest.mark.corpus
def test_scipy_only_for_large_graphs() -> None:
    assert not _imports_scipy("from skinet.system.load import load_system; system = load_system('skillsets/spot_arm.toml')[0]")
    assert _imports_scipy("from tests.verify.test_limits import pair_and_arm; system = pair_and_arm()")
