"""Product exploration against EXPECTED.md, hand-computed nets and a naive BFS (docs/semantics.md §3, §6)."""

from __future__ import annotations

import re
from collections import deque
from functools import cache
from itertools import product
from pathlib import Path

import numpy as np
import pytest

from skinet.lang.model import Skillset
from skinet.lang.parser import parse_skillset
from skinet.net.semantics import stabilize, steps
from skinet.system.model import System, build_system
from skinet.verify.component import CACHE_SIZE, explore_component, forget_component_graphs
from skinet.verify.ctl import Kripke
from skinet.verify.explore import StateSpace, explore
from tests.corpus import require_corpus

CORPUS = Path(__file__).resolve().parents[3] / "shared" / "corpus"

Combined = tuple[int, ...]

# file, stable markings without / with event seeds, edges without seeds, deadlocks
EXPECTED = [
    ("spot.rl", 124, 128, 374, 0),
    ("manipulator.rl", 4, 13, 7, 0),
    ("isae_robot/isae_robot.rl", 12, 16, 40, 0),
]

# One resource that can only be spent and one skill that spends it: a deadlock.
DEADEND = """
skillset deadend {
    resource {
        fuel {
            state { Full Empty }
            initial Full
            transition { Full -> Empty }
        }
    }
    skill drive {
        precondition { fueled: fuel == Full }
        start { fuel -> Empty }
        success arrived {}
    }
}
"""

# Starting `watch` while the light is off fails at once (invariant cascade):
# a step from the initial marking back to itself.
LOOPER = """
skillset looper {
    resource {
        light {
            state { Off On }
            initial Off
            transition all
        }
    }
    event {
        switch_on {
            guard light == Off
            effect light -> On
        }
    }
    skill watch {
        invariant { lit { guard light == On } }
        success done {}
    }
}
"""

# `flip` breaks both running skills' invariants at once; their effects on
# `last` conflict, so the order of the cascade decides the stable result.
FORK = """
skillset fork {
    resource {
        mode {
            state { A B }
            initial A
            transition all
        }
        last {
            state { None X Y }
            initial None
            transition all
        }
    }
    skill k1 {
        precondition { in_a: mode == A }
        invariant { a1 { guard mode == A effect last -> X } }
        success done {}
    }
    skill k2 {
        precondition { in_a: mode == A }
        invariant { a2 { guard mode == A effect last -> Y } }
        success done {}
    }
    skill flip {
        precondition { in_a: mode == A }
        start { mode -> B }
        success done {}
    }
}
"""


@cache
def corpus_skillset(name: str) -> Skillset:
    path = CORPUS / name
    if not path.exists():
        require_corpus()
    return parse_skillset(path.read_text(), str(path))


@cache
def text_skillset(text: str, rename: str | None = None) -> Skillset:
    if rename is not None:
        text = re.sub(r"skillset\s+(\w+)", f"skillset {rename}", text, count=1)
    return parse_skillset(text, "<test>")


def system_of(*skillsets: Skillset, props: str = "") -> System:
    return build_system("test", [(s, "") for s in skillsets], props)


def corpus_pair() -> System:
    return system_of(
        corpus_skillset("spot.rl"), corpus_skillset("manipulator.rl"),
        props=(CORPUS / "spot_manipulator.props").read_text(),
    )


def naive_bfs(system: System, event_seeds: bool) -> tuple[dict[Combined, int], dict[Combined, set[Combined]]]:
    """Depth and successors of every combined stable marking, one marking at a time."""
    comps = system.components
    initial = tuple(c.net.initial for c in comps)
    roots = list(product(*(sorted(stabilize(c.eventless, m)) for c, m in zip(comps, initial))))
    sources = set(roots)
    if event_seeds:
        for i, c in enumerate(comps):
            for t, results in steps(c.net, initial[i]):
                if t.kind == "event":
                    sources |= {r[:i] + (m,) + r[i + 1:] for m in results for r in roots}
    depth = dict.fromkeys(sources, 0)
    succ: dict[Combined, set[Combined]] = {}
    queue = deque(sorted(sources))
    while queue:
        m = queue.popleft()
        succ[m] = {m[:i] + (r,) + m[i + 1:] for i, c in enumerate(comps) for _, rs in steps(c.eventless, m[i]) for r in rs}
        for n in succ[m]:
            if n not in depth:
                depth[n] = depth[m] + 1
                queue.append(n)
    return depth, succ


def engine_depths(space: StateSpace) -> dict[Combined, int]:
    names = [g.name for g in space.components]
    return {
        tuple(space.marking(int(c))[n] for n in names): int(space.depth[c])
        for c in np.flatnonzero(space.stored())
    }


def deadlocks(space: StateSpace) -> int:
    return int(np.count_nonzero(Kripke(space).deadlock))


@pytest.mark.parametrize(("name", "plain", "seeded", "edges", "dead"), EXPECTED)
def test_corpus_component_figures(name: str, plain: int, seeded: int, edges: int, dead: int) -> None:
    system = system_of(corpus_skillset(name))
    without = explore(system, event_seeds=False)
    with_seeds = explore(system)
    assert without.complete and with_seeds.complete
    assert (without.markings, with_seeds.markings, without.edges) == (plain, seeded, edges)
    assert deadlocks(without) == dead
    assert without.markings == int(np.count_nonzero(without.stored())) == sum(without.layers)


def test_corpus_pair_figures() -> None:
    space = explore(corpus_pair())
    assert space.complete
    assert (space.markings, space.edges, deadlocks(space)) == (1628, 7638, 0)
    assert space.frontier().sum() == 0


@pytest.mark.parametrize("event_seeds", [False, True])
@pytest.mark.parametrize("files", [("spot.rl", "manipulator.rl"), ("isae_robot/isae_robot.rl", "manipulator.rl")])
def test_against_naive_bfs(files: tuple[str, str], event_seeds: bool) -> None:
    system = system_of(*(corpus_skillset(f) for f in files))
    space = explore(system, event_seeds=event_seeds)
    depth, succ = naive_bfs(system, event_seeds)
    assert engine_depths(space) == depth
    assert space.markings == len(depth)
    assert space.edges == sum(len(s) for s in succ.values())
    assert deadlocks(space) == sum(1 for s in succ.values() if not s)
    assert space.expanded_depth == max(depth.values())


@pytest.mark.parametrize("event_seeds", [False, True])
def test_depth_is_sum_of_component_depths(event_seeds: bool) -> None:
    """A marking's depth is the sum of its components' distances, least over the sources."""
    space = explore(corpus_pair(), event_seeds=event_seeds)
    graphs = space.components
    codes = np.flatnonzero(space.stored())
    digits = [space.digits(codes, i) for i in range(len(graphs))]
    if not event_seeds:
        assert all(len(g.roots) == 1 and not g.seeds for g in graphs)
        expected = sum(g.dist[d] for g, d in zip(graphs, digits))
    else:
        inf = np.iinfo(np.int64).max // 4
        from_root = [np.where(f < 0, inf, f)[d] for f, d in zip((_distances(g.succ, g.roots) for g in graphs), digits)]
        expected = np.minimum(sum(from_root), inf)
        for i, g in enumerate(graphs):
            for seed in g.seeds:
                via = np.where(_distances(g.succ, [seed]) < 0, inf, _distances(g.succ, [seed]))[digits[i]]
                expected = np.minimum(expected, via + sum(f for j, f in enumerate(from_root) if j != i))
    assert np.array_equal(space.depth[codes], expected)


def _distances(succ: list[list[int]], sources: list[int]) -> np.ndarray:
    dist = np.full(len(succ), -1, dtype=np.int64)
    queue = deque(sources)
    for s in sources:
        dist[s] = 0
    while queue:
        a = queue.popleft()
        for b in succ[a]:
            if dist[b] < 0:
                dist[b] = dist[a] + 1
                queue.append(b)
    return dist


# --- hand-computed nets ------------------------------------------------------------------


def test_deadend_by_hand() -> None:
    ss = text_skillset(DEADEND)
    space = explore(system_of(ss))
    net = space.components[0].net
    m0 = net.marking_of({"fuel.Full", "e_drive"})
    m1 = net.marking_of({"fuel.Empty", "i_drive"})
    m2 = net.marking_of({"fuel.Empty", "e_drive"})
    # drive.start: m0 -> m1; interrupt and success: m1 -> m2 (one edge); m2 is dead.
    assert engine_depths(space) == {(m0,): 0, (m1,): 1, (m2,): 2}
    assert (space.markings, space.edges, deadlocks(space)) == (3, 2, 1)
    assert space.complete and space.layers == [1, 1, 1] and space.expanded_depth == 2
    assert [s for s, _ in space.successors(space.code({"deadend": m1}))] == [space.code({"deadend": m2})]


def test_self_loop_step_by_hand() -> None:
    ss = text_skillset(LOOPER)
    plain = explore(system_of(ss), event_seeds=False)
    net = plain.components[0].net
    m0 = net.marking_of({"light.Off", "e_watch"})
    on = net.marking_of({"light.On", "e_watch"})
    running = net.marking_of({"light.On", "i_watch"})
    # watch.start then lit fails at once: back to m0, a self-loop and no deadlock.
    assert (plain.markings, plain.edges, deadlocks(plain)) == (1, 1, 0)
    assert plain.successors(0) == [(0, "looper:watch.start")]
    seeded = explore(system_of(ss))
    # switch_on seeds `on`; from there watch runs and stops (interrupt, success: one edge).
    assert engine_depths(seeded) == {(m0,): 0, (on,): 0, (running,): 1}
    assert (seeded.markings, seeded.edges, deadlocks(seeded)) == (3, 3, 0)


def test_cascade_fork_by_hand() -> None:
    """One step, two stable results: every order of simultaneous invariant failures."""
    ss = text_skillset(FORK)
    space = explore(system_of(ss))
    net = space.components[0].net
    both = net.marking_of({"mode.A", "last.None", "i_k1", "i_k2", "e_flip"})
    code = space.code({"fork": both})
    assert code is not None and space.stored()[code]
    after = {
        frozenset(net.marked(space.marking(s)["fork"])): label
        for s, label in space.successors(code) if label == "fork:flip.start"
    }
    assert set(after) == {
        frozenset({"mode.B", "last.X", "e_k1", "e_k2", "i_flip"}),
        frozenset({"mode.B", "last.Y", "e_k1", "e_k2", "i_flip"}),
    }
    depth, succ = naive_bfs(system_of(ss), True)
    assert (space.markings, space.edges) == (len(depth), sum(map(len, succ.values())))


def test_products_by_hand() -> None:
    dead, loop = text_skillset(DEADEND), text_skillset(LOOPER)
    # 3 x 1 markings; deadend's 2 edges plus looper's self-loop at each of the 3: no deadlock.
    space = explore(system_of(dead, loop), event_seeds=False)
    assert (space.markings, space.edges, deadlocks(space)) == (3, 5, 0)
    # Two deadends: a 3 x 3 grid, 2 x 3 edges each way, one deadlock in the corner.
    space = explore(system_of(dead, text_skillset(DEADEND, "deadend2")))
    assert (space.markings, space.edges, deadlocks(space)) == (9, 12, 1)
    assert sorted(space.depth.tolist()) == [0, 1, 1, 2, 2, 2, 3, 3, 4]
    assert space.layers == [1, 2, 3, 2, 1]


def test_live_marking_root() -> None:
    """Exploring from a later marking keeps only what it reaches."""
    ss = text_skillset(DEADEND)
    system = system_of(ss)
    net = system.component("deadend").net
    m1 = net.marking_of({"fuel.Empty", "i_drive"})
    space = explore(system, {"deadend": m1})
    assert (space.markings, space.edges, deadlocks(space)) == (2, 1, 1)


# --- truncation ----------------------------------------------------------------------------


@pytest.mark.parametrize("max_depth", [0, 1, 3, 7])
def test_max_depth_truncates_between_layers(max_depth: int) -> None:
    system = corpus_pair()
    full = explore(system)
    part = explore(system, max_depth=max_depth)
    assert not part.complete and part.expanded_depth == max_depth - 1
    assert part.layers == full.layers[: max_depth + 1]
    assert part.markings == sum(part.layers)
    mine = np.flatnonzero(part.stored())
    at = full.index(part.code_of(mine))  # part's markings in full's index space
    assert np.all(at >= 0) and np.array_equal(part.depth[mine], full.depth[at])
    elsewhere = np.array(full.stored())
    elsewhere[at] = False
    assert np.all(full.depth[elsewhere] > max_depth)
    assert part.frontier().sum() == part.layers[-1]
    kripke = Kripke(part)
    assert not np.any(kripke.deadlock & kripke.frontier)
    # Edges are those leaving expanded markings, each counted once.
    expanded = np.flatnonzero(part.expanded())
    assert part.edges == sum(len(part.successors(int(c))) for c in expanded)


def test_max_depth_beyond_the_end_is_complete() -> None:
    system = corpus_pair()
    full = explore(system)
    again = explore(system, max_depth=len(full.layers))
    assert again.complete and (again.markings, again.edges) == (full.markings, full.edges)


def test_zero_budget_is_truncated() -> None:
    space = explore(corpus_pair(), budget=0.0)
    assert not space.complete and space.expanded_depth == -1 and space.edges == 0
    assert space.markings == space.layers[0] == int(space.frontier().sum())


def test_progress_reports_the_markings_stored() -> None:
    seen: list[tuple[int, int]] = []
    space = explore(corpus_pair(), progress=lambda d, n, t: seen.append((d, n)))
    assert seen and [n for _, n in seen] == sorted(n for _, n in seen)
    assert seen[-1] == (space.expanded_depth + 1, space.markings)


def test_repeated_exploration_is_identical() -> None:
    system = corpus_pair()
    first, second = explore(system), explore(system)
    assert np.array_equal(first.depth, second.depth) and first.edges == second.edges


def test_component_graphs_are_memoised() -> None:
    system = corpus_pair()
    for c in system.components:
        forget_component_graphs(c.eventless)
    first, second = explore(system), explore(system)
    assert all(g.size > 1 for g in first.components)
    assert all(a is b for a, b in zip(first.components, second.components))
    net = system.components[0].eventless
    for c in system.components:
        forget_component_graphs(c.eventless)
    third = explore(system)
    assert all(a is not b for a, b in zip(first.components, third.components))
    assert np.array_equal(first.depth, third.depth)
    # Bounded: exploring from many live markings keeps the most recent only.
    for m in third.components[0].states[: CACHE_SIZE + 5]:
        explore_component("spot", net, [m])
    assert len(net.__dict__["_component_graphs"]) == CACHE_SIZE
