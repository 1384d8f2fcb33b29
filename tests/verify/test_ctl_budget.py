"""The budget bounds every CTL formula, whatever its nesting (issue 31, item 1; docs/commands.md "skinet ctl").

Once the deadline has passed, each remaining operator costs O(1): no fixpoint
starts and no pass over the markings is made, so the time past the budget does
not grow with the formula.  What was cut stays sound: every decided answer
(``lower`` proven, outside ``upper`` refuted) agrees with an untimed run.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from collections.abc import Callable
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skinet.lang.expr import And, Const, Expr, Implies, Not, Or
from skinet.props.formula import PlaceAtom, Temporal, Until
import skinet.verify.ctl as ctl
from skinet.verify.ctl import Kripke, Result, check
from skinet.verify.explore import Deadline, StateSpace, explore, explore_graphs
from tests.verify.test_ctl import PLACES, UNARY, lift, make_graph, systems
from tests.verify.test_limits import CORPUS, CountingDeadline, copies

OPERATORS = ("not", "and", "or", "implies") + UNARY + ("EU", "AU")
BUDGET = 0.5  # seconds; the property allows one more


def nested(data: st.DataObject, atoms: st.SearchStrategy[Expr], depth: int) -> Expr:
    """A formula nested exactly ``depth`` operators deep, each operator drawn from all of CTL's."""
    f = data.draw(atoms)
    for _ in range(depth):
        op = data.draw(st.sampled_from(OPERATORS))
        other = data.draw(atoms)
        left = data.draw(st.booleans())
        if op == "not":
            f = Not(f)
        elif op in ("and", "or", "implies"):
            a, b = (f, other) if left else (other, f)
            f = {"and": And, "or": Or, "implies": Implies}[op](a, b)
        elif op in UNARY:
            f = Temporal(op, f)
        else:
            a, b = (f, other) if left else (other, f)
            f = Until(op[0], a, b)
    return f


def chain(op: str, atom: Expr, other: Expr, depth: int) -> Expr:
    f = atom
    for _ in range(depth):
        f = Until(op[0], other, f) if op in ("EU", "AU") else Temporal(op, f)
    return f


# --- soundness: what a cut evaluation decides, the untimed one agrees with --------------------


def assert_sound(full: StateSpace, part: StateSpace, truth: Result, got: Result, f: Expr) -> None:
    lower, upper = lift(part, full, got.lower), lift(part, full, got.upper)
    stored = lift(part, full, part.stored())
    assert np.array_equal(truth.lower, truth.upper)
    assert not np.any(lower & ~upper), f
    assert not np.any(lower & ~truth.lower), f  # proven: true
    assert not np.any(stored & truth.lower & ~upper), f  # refuted: false


@settings(max_examples=200, deadline=None)
@given(data=st.data())
def test_every_decided_answer_agrees_with_the_untimed_one(data: st.DataObject) -> None:
    """Random systems, random deep formulas, the deadline expiring at any of its checks."""
    graphs = data.draw(systems(max_components=3, max_states=5))
    names = [g.name for g in graphs]
    atoms = st.builds(PlaceAtom, st.sampled_from(names), st.sampled_from(PLACES[:3])) | st.builds(Const, st.booleans())
    f = nested(data, atoms, data.draw(st.integers(1, 12)))
    full = explore_graphs(graphs)
    truth = check(Kripke(full), f)
    part = explore_graphs(graphs, max_depth=data.draw(st.integers(0, max(0, full.expanded_depth))))
    part.deadline = CountingDeadline(data.draw(st.integers(0, 60)))
    k = Kripke(part)
    got = check(k, f)
    assert_sound(full, part, truth, got, f)
    if part.complete and not k.cut:
        assert np.array_equal(got.lower, truth.lower) and np.array_equal(got.upper, truth.upper), f


@cache
def sparse() -> StateSpace:
    """5 + 5 corpus copies, 4 layers deep without seeds: 9 471 markings stored sparsely (the large copies' storage)."""
    system = copies(5, 5)
    space = explore(system, system.initial_marking(), max_depth=4, event_seeds=False, memory_limit=None)
    assert space.codes is not None and not space.complete
    return space


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_every_decided_answer_agrees_on_sparse_storage(data: st.DataObject) -> None:
    """The same on sorted codes (binary-search lookups, chunked degree passes), the deadline at any check."""
    space = sparse()
    f = nested(data, atoms_of(space), data.draw(st.integers(1, 12)))
    space.deadline = Deadline(None)
    truth = check(Kripke(space), f)
    space.deadline = CountingDeadline(data.draw(st.integers(0, 80)))
    k = Kripke(space)
    got = check(k, f)
    assert not np.any(got.lower & ~got.upper), f
    assert not np.any(got.lower & ~truth.lower), f  # proven: proven untimed
    assert not np.any(truth.upper & ~got.upper), f  # refuted: refuted untimed
    if not k.cut:
        assert np.array_equal(got.lower, truth.lower) and np.array_equal(got.upper, truth.upper), f


# --- no work past the deadline: counted, whatever the machine's load -------------------------

PASSES = ("_local_degrees", "_initial", "_chunks", "predecessor_chunks", "successor_in", "_box_successor_in",
          "bound_ranks", "edges")


def passes_after_deadline(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Names of the passes over the markings started once the deadline had expired."""
    late: list[str] = []
    for name in PASSES:
        original = getattr(Kripke, name, None)
        if original is None:
            continue

        def counted(self: Kripke, *args: object, _original: Callable[..., object] = original, _name: str = name,
                    **kwargs: object) -> object:
            if self.deadline.hit:
                late.append(_name)
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(Kripke, name, counted)
    return late


@pytest.mark.parametrize("op", UNARY + ("EU", "AU"))
def test_past_the_deadline_outer_operators_make_no_pass(op: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The deadline expires inside the innermost operator: the 39 around it start nothing.

    Before the fix, each A[U] around it ran its degree pass twice (``_pair``).
    """
    graphs = [make_graph("a", [1, 2, 4, 0], [{1}, {2}, {3}, {0}], [False] * 4, [0], []),
              make_graph("b", [1, 2, 4], [{1}, {2}, {0}], [False, True, False], [0], [])]
    p, q = PlaceAtom("a", "p0"), Not(PlaceAtom("b", "p1"))
    full = explore_graphs(graphs)
    late = passes_after_deadline(monkeypatch)
    for checks in range(0, 12):
        space = explore_graphs(graphs, max_depth=2)  # a frontier: lower and upper both run
        space.deadline = CountingDeadline(checks)
        k = Kripke(space)
        got = check(k, chain(op, p, q, 40))
        assert k.cut and k.truncated_by == "depth"
        assert late == [], (checks, late)
        assert_sound(full, space, check(Kripke(full), chain(op, p, q, 40)), got, op)


# --- wall time on large corpus copies --------------------------------------------------------


@cache
def large() -> tuple[StateSpace, int]:
    """5 Spot + 5 arm corpus copies, explored 8 layers deep without event seeds: 2.0 M markings in well under a second."""
    system = copies(5, 5)
    marking = system.initial_marking()
    space = explore(system, marking, max_depth=8, event_seeds=False, memory_limit=None)
    start = space.code(marking)
    assert start is not None and space.markings > 1_500_000 and not space.complete
    return space, start


def atoms_of(space: StateSpace) -> st.SearchStrategy[Expr]:
    pairs = [(g.name, p) for g in space.components for p in g.net.places]
    return st.sampled_from(pairs).map(lambda sp: PlaceAtom(*sp)) | st.builds(Const, st.booleans())


def timed(space: StateSpace, start: int, f: Expr) -> float:
    """What ``skinet ctl`` does after exploring: the structure, the check, the verdict and counts."""
    t0 = time.perf_counter()
    space.deadline = Deadline.after(BUDGET)
    k = Kripke(space)
    r = check(k, f)
    assert not np.any(r.lower & ~r.upper)
    bool(r.lower[start]), bool(r.upper[start]), int(r.lower.sum()), int((r.upper & ~r.lower).sum())
    return time.perf_counter() - t0


@pytest.mark.parametrize("op", ("AU", "AF", "EU", "EG", "AX"))
def test_nested_forty_deep_within_budget(op: str) -> None:
    """Before the fix, A[U] 30 deep took 3.2 s on 1 M markings with a 0.5 s budget (each operator's degree pass, twice)."""
    space, start = large()
    g = space.components
    f = chain(op, PlaceAtom(g[0].name, g[0].net.places[0]), Not(PlaceAtom(g[-1].name, g[-1].net.places[0])), 40)
    elapsed = timed(space, start, f)
    assert elapsed <= BUDGET + 1, f"{op} 40 deep: {elapsed:.2f} s for a {BUDGET} s budget"


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_random_nested_formulas_within_budget(data: st.DataObject) -> None:
    space, start = large()
    f = nested(data, atoms_of(space), data.draw(st.integers(1, 40)))
    elapsed = timed(space, start, f)
    assert elapsed <= BUDGET + 1, f"{elapsed:.2f} s for a {BUDGET} s budget: {f}"


def test_past_the_deadline_a_state_formula_reads_at_most_eight_atoms(monkeypatch: pytest.MonkeyPatch) -> None:
    """A small one is still answered (``spot:Busy`` after a cut exploration); a large one is undecided.

    Before, 40 connectives of atoms took 0.84 s past the deadline on 2 M markings, 200 took 3.5 s.
    """
    graphs = [make_graph("a", [1, 2, 4, 0], [{1}, {2}, {3}, {0}], [False] * 4, [0], [])]
    space = explore_graphs(graphs)
    reads: list[PlaceAtom] = []
    original = ctl.place_values
    monkeypatch.setattr(ctl, "place_values", lambda s, a, flat=True: reads.append(a) or original(s, a, flat))
    p, q = PlaceAtom("a", "p0"), PlaceAtom("a", "p1")
    small: Expr = Or(p, And(q, Not(p)))
    large: Expr = p
    for n in range(200):
        large = And(large, q) if n % 2 else Or(large, Not(p))
    untimed = check(Kripke(space), small)
    space.deadline = Deadline(0.0)
    k = Kripke(space)
    reads.clear()
    got = check(k, small)
    assert len(reads) == 3 and np.array_equal(got.lower, untimed.lower) and np.array_equal(got.upper, untimed.lower)
    reads.clear()
    got = check(k, large)
    assert len(reads) == ctl.GRACE_ATOMS == 8
    assert not got.lower.any() and got.upper.all() and k.truncated_by == "budget"


def test_skinet_ctl_answers_a_forty_deep_formula_within_its_budget(tmp_path: Path) -> None:
    """The command end to end, the way the issue measured it (6.6 s for 10 deep with --budget 2)."""
    if not CORPUS.exists():
        pytest.skip(f"{CORPUS} not found")
    entries = []
    for file, name in (("spot.rl", "spot"), ("manipulator.rl", "manipulator")):
        text = (CORPUS / file).read_text()
        for k in range(1, 6):
            renamed = name if k == 1 else f"{name}{k}"
            (tmp_path / f"{renamed}.rl").write_text(re.sub(rf"skillset\s+{name}\b", f"skillset {renamed}", text, count=1))
            entries.append(f'[[skillsets]]\nmodel = "{renamed}.rl"\n')
    (tmp_path / "copies.props").write_text((CORPUS / "spot_manipulator.props").read_text())
    (tmp_path / "copies.toml").write_text('[system]\nname = "copies"\nproperties = "copies.props"\n\n' + "\n".join(entries))
    deep = "spot:i_go_to_waypoint"
    for _ in range(40):
        deep = f"A[manipulator:e_arm_moving_to_HP U {deep}]"

    def ctl(formula: str) -> tuple[float, dict]:
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "skinet_cli.main", "ctl", str(tmp_path / "copies.toml"), formula,
                               "--budget", "2", "--max-depth", "8", "--no-seeds", "--json"],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        return time.perf_counter() - t0, json.loads(done.stdout)[0]

    base, answer = ctl("AG true")  # start-up, loading and the exploration: no fixpoint
    assert answer["start"] == "holds" and answer["markings"] > 100_000  # 2.0 M on an idle machine
    wall, answer = ctl(deep)
    assert answer["start"] == "undecided" and answer["truncated_by"] is not None
    assert wall <= base + 2 + 1, f"{wall:.2f} s against {base:.2f} s without fixpoints, budget 2 s"
