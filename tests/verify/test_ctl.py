"""Three-valued CTL against a direct set-based definition (docs/semantics.md §6).

Random Kripke structures are products of random component graphs, built
directly (:class:`ComponentGraph` with random successor lists and self-loops);
a component state is an ``int`` whose bits 0..2 are the places ``p0..p2`` of
a tiny net, so :class:`PlaceAtom` works on them.  The reference semantics is a
textbook fixpoint computation on the explicit product graph, where a deadlock
is a sink with a self-loop.
"""

from __future__ import annotations

from collections import deque
from itertools import product
from math import prod

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skinet.lang.expr import And, Const, Expr, Implies, Not, Or
from skinet.lang.parser import parse_skillset
from skinet.net.petrinet import PetriNet
from skinet.props.formula import PlaceAtom, Temporal, Until, is_temporal
from skinet.props.parser import parse_formula
from skinet.system.model import build_system
from skinet.verify.component import ComponentGraph
from skinet.verify.ctl import Kripke, Result, check
from skinet.verify.explore import Deadline, StateSpace, explore, explore_graphs

State = tuple[int, ...]
PLACES = ("p0", "p1", "p2", "x3", "x4", "x5", "x6")
UNARY = ("EX", "AX", "EF", "AF", "EG", "AG")


def make_graph(name: str, bits: list[int], succ: list[set[int]], loop: list[bool],
               roots: list[int], seeds: list[int]) -> ComponentGraph:
    """A component graph given by hand; state ``i`` carries the atoms ``bits[i]``."""
    states = [(i << 3) | b for i, b in enumerate(bits)]
    net = PetriNet(name, PLACES, (), states[roots[0]])
    lists = [sorted(s - {a}) for a, s in enumerate(succ)]
    labels = {(a, b): f"t{a}_{b}" for a, bs in enumerate(lists) for b in bs}
    labels |= {(a, a): f"t{a}_{a}" for a in range(len(states)) if loop[a]}
    return ComponentGraph(
        name, net, states, {m: i for i, m in enumerate(states)}, lists, np.array(loop, dtype=bool), labels,
        _bfs(lists, roots), _bfs(lists, roots + seeds), roots, seeds,
    )


def _bfs(succ: list[list[int]], sources: list[int]) -> np.ndarray:
    dist = np.full(len(succ), -1, dtype=np.int64)
    queue = deque(sources)
    dist[sources] = 0
    while queue:
        a = queue.popleft()
        for b in succ[a]:
            if dist[b] < 0:
                dist[b] = dist[a] + 1
                queue.append(b)
    return dist


@st.composite
def component(draw: st.DrawFn, name: str, max_states: int) -> ComponentGraph:
    n = draw(st.integers(1, max_states))
    idx = st.integers(0, n - 1)
    bits = draw(st.lists(st.integers(0, 7), min_size=n, max_size=n))
    succ = [draw(st.sets(idx, max_size=3)) for _ in range(n)]
    loop = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    roots = sorted(draw(st.sets(idx, min_size=1, max_size=2)))
    seeds = sorted(draw(st.sets(idx, max_size=2)) - set(roots))
    return make_graph(name, bits, succ, loop, roots, seeds)


@st.composite
def systems(draw: st.DrawFn, max_components: int = 2, max_states: int = 5) -> list[ComponentGraph]:
    k = draw(st.integers(1, max_components))
    return [draw(component(f"c{i}", max_states)) for i in range(k)]


def formulas(names: list[str], temporal_depth: int = 2) -> st.SearchStrategy[Expr]:
    """State formulas over ``p0..p2`` of each component, with temporal operators nested up to twice."""
    atoms = st.builds(PlaceAtom, st.sampled_from(names), st.sampled_from(PLACES[:3])) | st.builds(Const, st.booleans())

    def boolean(inner: st.SearchStrategy[Expr]) -> st.SearchStrategy[Expr]:
        return inner | st.builds(Not, inner) | st.builds(And, inner, inner) | st.builds(Or, inner, inner) | st.builds(Implies, inner, inner)

    level: st.SearchStrategy[Expr] = boolean(atoms)
    for _ in range(temporal_depth):
        inner = level
        level = boolean(
            st.builds(Temporal, st.sampled_from(UNARY), inner)
            | st.builds(Until, st.sampled_from("EA"), inner, inner)
            | atoms
        )
    return level


def ranked_formulas(names: list[str]) -> st.SearchStrategy[Expr]:
    """``AF f`` and ``A[f U g]`` at the top, whose ranks are compared too."""
    sub = formulas(names, temporal_depth=1)
    return st.builds(Temporal, st.just("AF"), sub) | st.builds(Until, st.just("A"), sub, sub)


def some_formulas(names: list[str]) -> st.SearchStrategy[list[Expr]]:
    return st.lists(formulas(names) | ranked_formulas(names), min_size=1, max_size=6)


class Explicit:
    """The product graph built tuple by tuple, and CTL by textbook fixpoints on sets."""

    def __init__(self, graphs: list[ComponentGraph]):
        self.graphs = graphs
        roots = list(product(*(g.roots for g in graphs)))
        sources = set(roots)
        for i, g in enumerate(graphs):
            sources |= {r[:i] + (s,) + r[i + 1:] for s in g.seeds for r in roots}
        self.succ: dict[State, set[State]] = {}
        self.depth = dict.fromkeys(sources, 0)
        queue = deque(sources)
        while queue:
            m = queue.popleft()
            nxt = set()
            for i, g in enumerate(graphs):
                targets = set(g.succ[m[i]]) | ({m[i]} if g.loop[m[i]] else set())
                nxt |= {m[:i] + (b,) + m[i + 1:] for b in targets}
            self.succ[m] = nxt or {m}  # a deadlock is a sink with a self-loop
            for n in nxt:
                if n not in self.depth:
                    self.depth[n] = self.depth[m] + 1
                    queue.append(n)
        self.states = set(self.succ)
        sizes = [g.size for g in graphs]
        self.stride = [prod(sizes[i + 1:]) for i in range(len(sizes))]
        self.deadlocks = {m for m in self.states if self.succ[m] == {m} and not any(g.loop[m[i]] for i, g in enumerate(graphs))}

    def code(self, m: State) -> int:
        return sum(a * s for a, s in zip(m, self.stride))

    def layers(self) -> list[int]:
        counts = [0] * (1 + max(self.depth.values()))
        for d in self.depth.values():
            counts[d] += 1
        return counts

    def ex(self, z: set[State]) -> set[State]:
        return {m for m in self.states if self.succ[m] & z}

    def ax(self, z: set[State]) -> set[State]:
        return {m for m in self.states if self.succ[m] <= z}

    def lfp(self, step) -> tuple[set[State], dict[State, int]]:
        """Least fixpoint by Kleene iteration; the rank is the iteration a state joins in."""
        z: set[State] = set()
        rank: dict[State, int] = {}
        level = 0
        while True:
            nz = step(z)
            if nz == z:
                return z, rank
            for m in nz - z:
                rank[m] = level
            z, level = nz, level + 1

    def gfp(self, step) -> set[State]:
        z = set(self.states)
        while (nz := step(z)) != z:
            z = nz
        return z

    def sat(self, f: Expr) -> set[State]:
        return self.sat_rank(f)[0]

    def sat_rank(self, f: Expr) -> tuple[set[State], dict[State, int]]:
        S = self.states
        if isinstance(f, Const):
            return (set(S) if f.value else set()), {}
        if isinstance(f, PlaceAtom):
            i = next(i for i, g in enumerate(self.graphs) if g.name == f.skillset)
            bit = 1 << PLACES.index(f.place)
            return {m for m in S if self.graphs[i].states[m[i]] & bit}, {}
        if isinstance(f, Not):
            return S - self.sat(f.arg), {}
        if isinstance(f, And):
            return self.sat(f.left) & self.sat(f.right), {}
        if isinstance(f, Or):
            return self.sat(f.left) | self.sat(f.right), {}
        if isinstance(f, Implies):
            return (S - self.sat(f.left)) | self.sat(f.right), {}
        if isinstance(f, Until):
            a, b = self.sat(f.left), self.sat(f.right)
            nxt = self.ex if f.quantifier == "E" else self.ax
            return self.lfp(lambda z: b | (a & nxt(z)))
        assert isinstance(f, Temporal)
        a = self.sat(f.arg)
        return {
            "EX": lambda: (self.ex(a), {}),
            "AX": lambda: (self.ax(a), {}),
            "EF": lambda: self.lfp(lambda z: a | self.ex(z)),
            "AF": lambda: self.lfp(lambda z: a | self.ax(z)),
            "EG": lambda: (self.gfp(lambda z: a & self.ex(z)), {}),
            "AG": lambda: (self.gfp(lambda z: a & self.ax(z)), {}),
        }[f.op]()


def codes_of(ref: Explicit, states: set[State]) -> set[int]:
    return {ref.code(m) for m in states}


def as_set(mask: np.ndarray, space: StateSpace | None = None) -> set[int]:
    """Codes where ``mask`` (over ``space``'s index space; default: index = code) holds."""
    idx = np.flatnonzero(mask)
    return set((idx if space is None else space.code_of(idx)).tolist())


def lift(part: StateSpace, full: StateSpace, values: np.ndarray, fill: object = False) -> np.ndarray:
    return part.transfer(values, full, fill)


def ranked(f: Expr) -> bool:
    return isinstance(f, Until) and f.quantifier == "A" or isinstance(f, Temporal) and f.op == "AF"


# --- complete explorations: engine == definition --------------------------------------------


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_ctl_matches_definition(data: st.DataObject) -> None:
    graphs = data.draw(systems())
    space = explore_graphs(graphs)
    ref = Explicit(graphs)
    assert space.complete and as_set(space.stored(), space) == codes_of(ref, ref.states)
    assert space.markings == len(ref.states) and space.layers == ref.layers()
    kripke = Kripke(space)
    assert as_set(kripke.deadlock, space) == codes_of(ref, ref.deadlocks)
    names = [g.name for g in graphs]
    for f in data.draw(some_formulas(names)):
        result = check(kripke, f)
        expected, rank = ref.sat_rank(f)
        assert as_set(result.lower, space) == as_set(result.upper, space) == codes_of(ref, expected), f
        if ranked(f):
            assert result.rank is not None
            got = {int(space.code_of(np.array([i]))[0]): int(result.rank[i]) for i in np.flatnonzero(result.lower)}
            assert got == {ref.code(m): r for m, r in rank.items()}, f


@pytest.mark.parametrize("op", UNARY + ("EU", "AU"))
@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_each_operator(op: str, data: st.DataObject) -> None:
    """Every operator on its own, applied to atoms and to one nested operator."""
    graphs = data.draw(systems())
    names = [g.name for g in graphs]
    sub = formulas(names, temporal_depth=1)
    f: Expr
    if op in UNARY:
        f = Temporal(op, data.draw(sub))
    else:
        f = Until(op[0], data.draw(sub), data.draw(sub))
    ref = Explicit(graphs)
    space = explore_graphs(graphs)
    result = check(Kripke(space), f)
    assert as_set(result.lower, space) == as_set(result.upper, space) == codes_of(ref, ref.sat(f))


# --- truncated explorations: lower <= truth <= upper ----------------------------------------


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_truncation_is_sound(data: st.DataObject) -> None:
    graphs = data.draw(systems(max_components=3, max_states=5))
    full = explore_graphs(graphs)
    max_depth = data.draw(st.integers(0, max(0, full.expanded_depth)))
    part = explore_graphs(graphs, max_depth=max_depth)
    assert_sound(full, part, data.draw(some_formulas([g.name for g in graphs])))


def assert_sound(full: StateSpace, part: StateSpace, fs: list[Expr]) -> None:
    """What a truncated run proves or refutes, the complete run agrees with."""
    complete, truncated = Kripke(full), Kripke(part)
    assert not np.any(truncated.deadlock & truncated.frontier)
    stored = lift(part, full, part.stored())
    deadlock, expanded = lift(part, full, truncated.deadlock), lift(part, full, truncated.expanded)
    assert not np.any(deadlock & ~complete.deadlock)
    assert np.array_equal(deadlock, complete.deadlock & expanded)
    for f in fs:
        truth, got = check(complete, f), check(truncated, f)
        r = Result(lift(part, full, got.lower), lift(part, full, got.upper),
                   None if got.rank is None else lift(part, full, got.rank, 0))
        assert np.array_equal(truth.lower, truth.upper)
        assert not np.any(r.lower & ~r.upper), f  # undecided exactly where they differ
        assert not np.any((r.lower | r.upper) & ~stored), f
        assert not np.any(r.lower & ~truth.lower), f
        assert not np.any(stored & truth.lower & ~r.upper), f
        if part.complete:
            assert np.array_equal(r.lower, r.upper)
        if ranked(f):
            assert r.rank is not None and truth.rank is not None
            proven = r.lower
            # A truncated rank bounds the true one; with state-formula arguments it is exact.
            assert np.all(r.rank[proven] >= truth.rank[proven]), f
            args = [f.arg] if isinstance(f, Temporal) else [f.left, f.right]
            if not any(is_temporal(a) for a in args):
                assert np.array_equal(r.rank[proven], truth.rank[proven]), f


def test_budget_zero_on_random_graph() -> None:
    graphs = [make_graph("c0", [1, 0, 2], [{1}, {2}, set()], [False] * 3, [0], [])]
    part = explore_graphs(graphs, budget=0.0)
    assert not part.complete and part.markings == 1
    r = check(Kripke(part), Temporal("AF", PlaceAtom("c0", "p1")))
    assert not r.lower.any() and as_set(r.upper, part) == {0}


# --- deadlocks, self-loops and ranks on hand-made structures ---------------------------------


def test_chain_with_deadlock() -> None:
    """0 -> 1 -> 2 (dead); p0 at 0, p1 at 1, p2 at 2."""
    space = explore_graphs([make_graph("c", [1, 2, 4], [{1}, {2}, set()], [False] * 3, [0], [])])
    k = Kripke(space)
    p = [PlaceAtom("c", f"p{i}") for i in range(3)]
    assert as_set(k.deadlock) == {2}
    assert as_set(check(k, Temporal("AF", p[2])).lower) == {0, 1, 2}
    assert check(k, Temporal("AF", p[2])).rank.tolist() == [2, 1, 0]
    assert as_set(check(k, Temporal("AF", p[0])).lower) == {0}  # the deadlock never reaches p0
    assert as_set(check(k, Temporal("EG", p[2])).lower) == {2}  # the sink loops on itself
    assert as_set(check(k, Temporal("AX", p[2])).lower) == {1, 2}
    assert as_set(check(k, Temporal("EX", Not(p[2]))).lower) == {0}
    assert as_set(check(k, Until("A", Or(p[0], p[1]), p[2])).lower) == {0, 1, 2}
    assert as_set(check(k, Until("E", p[0], p[1])).lower) == {0, 1}


def test_self_loop_blocks_af() -> None:
    """0 <-> 0 loop and 0 -> 1: a path can stay at 0 forever."""
    space = explore_graphs([make_graph("c", [0, 1], [{1}, set()], [True, False], [0], [])])
    k = Kripke(space)
    p0 = PlaceAtom("c", "p0")
    assert as_set(check(k, Temporal("AF", p0)).lower) == {1}
    assert as_set(check(k, Temporal("EF", p0)).lower) == {0, 1}
    assert as_set(check(k, Temporal("EG", Not(p0))).lower) == {0}
    assert not k.deadlock[0] and k.deadlock[1]


def test_deadlock_of_one_component_is_not_global() -> None:
    """A component stuck alone does not block the product: the other still moves."""
    dead = make_graph("a", [0, 1], [{1}, set()], [False, False], [0], [])
    live = make_graph("b", [0, 2], [{1}, {0}], [False, False], [0], [])
    k = Kripke(explore_graphs([dead, live]))
    assert not k.deadlock.any()
    assert as_set(check(k, Temporal("AG", Temporal("EF", PlaceAtom("b", "p1")))).lower) == {0, 1, 2, 3}


def test_parsed_formulas_on_a_skillset() -> None:
    text = """
    skillset deadend {
        resource { fuel { state { Full Empty } initial Full transition { Full -> Empty } } }
        skill drive {
            precondition { fueled: fuel == Full }
            start { fuel -> Empty }
            success arrived {}
        }
    }
    """
    ss = parse_skillset(text, "<test>")
    kripke = Kripke(explore(build_system("t", [(ss, "")], "")))
    names = {"deadend": ss}

    def holds(formula: str) -> Result:
        return check(kripke, parse_formula(formula, names))

    # Codes in BFS order: initial (depth 0), running (1), dead end (2).
    net = kripke.space.components[0].net
    assert kripke.space.code({"deadend": net.marking_of({"fuel.Empty", "e_drive"})}) == 2
    assert as_set(holds("AF deadend:Empty").lower) == {0, 1, 2}
    assert as_set(holds("AF deadend:Full").lower) == {0}
    assert as_set(holds("EG deadend:Empty").lower) == {1, 2}
    assert as_set(holds("EG deadend:Empty and deadend:e_drive").lower) == {2}
    assert as_set(holds("A[deadend:Full U deadend:i_drive]").lower) == {0, 1}
    assert as_set(holds("not EX true").lower) == set()
    assert holds("AG AF deadend:Empty").lower.all()


# --- what needs no exploration, and what the budget stops (issue 25, item 5) -----------------


def test_constant_formulas_are_answered_on_a_cut_exploration() -> None:
    """Every marking has a successor, so a temporal operator of a constant is that constant."""
    graphs = [make_graph("c", [1, 2, 4], [{1}, {2}, set()], [False] * 3, [0], [])]
    part = explore_graphs(graphs, budget=0.0)
    assert not part.complete and part.markings == 1
    k = Kripke(part)
    p0 = PlaceAtom("c", "p0")
    true, false = Const(True), Const(False)
    for f, value in [(Temporal("AG", true), True), (Temporal("AG", Temporal("AG", true)), True),
                     (Temporal("EX", true), True), (Not(Temporal("AX", false)), True),
                     (Until("A", p0, true), True), (Or(p0, Temporal("EF", true)), True),
                     (Temporal("EF", false), False), (Temporal("AF", false), False),
                     (Until("E", true, false), False), (And(p0, Temporal("EG", false)), False),
                     (Implies(Temporal("AG", false), p0), True)]:
        r = check(k, f)
        assert as_set(r.lower) == as_set(r.upper) == ({0} if value else set()), f
    assert check(k, Temporal("AF", true)).rank[k.stored].tolist() == [0]
    assert as_set(check(k, Temporal("AG", p0)).upper) == {0}  # not a constant: still undecided
    assert not check(k, Temporal("AG", p0)).lower.any()


def count_fixpoints(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    calls: list[str] = []
    for name in ("ex", "ax", "eu", "au", "eg", "af"):
        original = getattr(Kripke, name)

        def counted(self, *args, _original=original, _name=name, **kwargs):  # type: ignore[no-untyped-def]
            calls.append(_name)
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(Kripke, name, counted)
    return calls


def test_nested_operators_cost_one_fixpoint_each(monkeypatch: pytest.MonkeyPatch) -> None:
    """``AG f`` reuses f's result: 8 nested AGs are 8 fixpoints, not 2^8 - 1 (it was 6.5 s on 3+3 copies)."""
    graphs = [make_graph("a", [1, 2, 0], [{1}, {2}, {0}], [False] * 3, [0], []),
              make_graph("b", [1, 2], [{1}, {0}], [True, False], [0], [])]
    k = Kripke(explore_graphs(graphs))
    p = Not(PlaceAtom("a", "p2"))
    nested: Expr = p
    for _ in range(8):
        nested = Temporal("AG", nested)
    calls = count_fixpoints(monkeypatch)
    result = check(k, nested)
    assert calls == ["eu"] * 8  # complete and exact: one run per operator
    assert np.array_equal(result.lower, check(k, Temporal("AG", p)).lower)


def test_past_the_deadline_no_fixpoint_starts(monkeypatch: pytest.MonkeyPatch) -> None:
    graphs = [make_graph("a", [1, 2, 0], [{1}, {2}, {0}], [False] * 3, [0], [])]
    k = Kripke(explore_graphs(graphs))
    k.deadline = Deadline(0.0)  # the budget ran out after the exploration
    calls = count_fixpoints(monkeypatch)
    nested: Expr = PlaceAtom("a", "p0")
    for op in ("AG", "EF", "AF", "EG", "AX", "EX", "AG", "AG"):
        nested = Temporal(op, nested)
    result = check(k, Or(nested, Until("A", nested, PlaceAtom("a", "p1"))))
    assert calls == []
    assert not result.lower.any() and result.upper.all()
    assert k.truncated_by == "budget"
    assert as_set(check(k, Temporal("AG", Const(True))).lower) == {0, 1, 2}  # constants still answered
