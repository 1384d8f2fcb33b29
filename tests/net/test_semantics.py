"""Firing, priorities and invariant cascades (docs/semantics.md §3, *Priority*)."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from skinet.lang.model import Skillset
from skinet.lang.parser import parse_skillset
from skinet.net.build import build_net, idle_place, resource_place, running_place
from skinet.net.petrinet import PetriNet, Transition
from skinet.net.semantics import (
    enabled,
    fire,
    invariants_enabled,
    is_enabled,
    is_stable,
    stabilize,
    stable_successors,
    steps,
)
from skinet.net.union import union

CASCADE = """
skillset c {
    resource {
        mode { state { Idle Busy } initial Idle transition all }
        power { state { Off On } initial On transition all }
        light { state { Dark Red Green } initial Dark transition all }
    }
    // its own start breaks its invariant
    skill selfish {
        start mode -> Busy
        invariant needs_idle { guard mode == Idle effect light -> Red }
    }
    skill night { invariant dark { guard light == Dark } }
    skill watcher { invariant needs_power { guard power == On effect light -> Green } }
    skill red { invariant needs_power { guard power == On effect light -> Red } }
    skill restorer { invariant needs_power { guard power == On effect power -> On } }
    skill cutter { start power -> Off }
}
"""

SKILLS = ("selfish", "night", "watcher", "red", "restorer", "cutter")


@pytest.fixture(scope="module")
def net() -> PetriNet:
    return build_net(parse_skillset(CASCADE))


def marking(net: PetriNet, mode: str = "Idle", power: str = "On", light: str = "Dark", running: tuple[str, ...] = ()) -> int:
    places = {f"mode.{mode}", f"power.{power}", f"light.{light}"}
    places |= {f"i_{k}" if k in running else f"e_{k}" for k in SKILLS}
    return net.marking_of(places)


def tr(net: PetriNet, tid: str) -> Transition:
    (t,) = [t for t in net.transitions if t.id == tid]
    return t


def variant(net: PetriNet, name: str, m: int) -> Transition:
    """The one variant of logical transition ``name`` enabled at ``m``."""
    (t,) = [t for t in net.transitions if t.name == name and is_enabled(t, m)]
    return t


def ids(ts: list[Transition]) -> list[str]:
    return [t.id for t in ts]


def test_fire_and_is_enabled(net: PetriNet) -> None:
    m0 = net.initial
    assert m0 == marking(net)
    start = tr(net, "cutter.start#2")  # the variant from power == On
    assert start is variant(net, "cutter.start", m0)
    assert not is_enabled(tr(net, "cutter.start"), m0)
    m1 = fire(start, m0)
    assert m1 == marking(net, power="Off", running=("cutter",))
    assert not is_enabled(start, m1)


def test_initial_marking_is_stable_and_enables_every_start(net: PetriNet) -> None:
    m0 = net.initial
    assert is_stable(net, m0)
    assert invariants_enabled(net, m0) == []
    assert ids(enabled(net, m0)) == [
        "selfish.start", "night.start", "watcher.start", "red.start", "restorer.start", "cutter.start#2",
    ]  # fmt: skip
    assert stabilize(net, m0) == frozenset({m0})


def test_start_breaking_its_own_invariant(net: PetriNet) -> None:
    m0 = net.initial
    start = tr(net, "selfish.start")
    transient = fire(start, m0)
    assert transient == marking(net, mode="Busy", running=("selfish",))
    assert not is_stable(net, transient)
    # priority: at a transient marking only invariant transitions are firable
    assert ids(invariants_enabled(net, transient)) == ["selfish.inv.needs_idle"]
    assert ids(enabled(net, transient)) == ["selfish.inv.needs_idle"]
    for other in ("selfish.interrupt", "night.start", "cutter.start#2"):
        assert is_enabled(tr(net, other), transient)
    # the cascade: the skill stops at once, its invariant effect applied, mode stays Busy
    after = marking(net, mode="Busy", light="Red")
    assert stable_successors(net, m0, start) == frozenset({after})
    assert stabilize(net, transient) == frozenset({after})


def test_cascade_chain_through_another_skill(net: PetriNet) -> None:
    # night runs while the light is Dark; selfish's invariant turns it Red,
    # which breaks night's invariant in turn: a cascade of two invariant failures.
    m = marking(net, running=("night",))
    assert is_stable(net, m)
    start = tr(net, "selfish.start")
    assert start in enabled(net, m)
    mid = fire(tr(net, "selfish.inv.needs_idle"), fire(start, m))
    assert ids(enabled(net, mid)) == ["night.inv.dark"]
    assert stable_successors(net, m, start) == frozenset({marking(net, mode="Busy", light="Red")})


def test_start_breaking_another_running_skills_invariant(net: PetriNet) -> None:
    m = marking(net, running=("watcher",))
    start = variant(net, "cutter.start", m)
    transient = fire(start, m)
    assert ids(enabled(net, transient)) == ["watcher.inv.needs_power"]
    assert stable_successors(net, m, start) == frozenset(
        {marking(net, power="Off", light="Green", running=("cutter",))}
    )


def test_two_invariants_with_different_effects_give_every_order(net: PetriNet) -> None:
    m = marking(net, running=("watcher", "red"))
    start = variant(net, "cutter.start", m)
    transient = fire(start, m)
    assert ids(enabled(net, transient)) == ["watcher.inv.needs_power", "red.inv.needs_power"]
    # watcher then red ends Red; red then watcher ends Green
    assert stable_successors(net, m, start) == frozenset(
        {
            marking(net, power="Off", light="Red", running=("cutter",)),
            marking(net, power="Off", light="Green", running=("cutter",)),
        }
    )


def test_an_invariant_effect_can_save_another_skill(net: PetriNet) -> None:
    # restorer's invariant turns the power back on: if it fails first, watcher's
    # invariant holds again and watcher keeps running; every order is kept.
    m = marking(net, running=("watcher", "restorer"))
    start = variant(net, "cutter.start", m)
    assert stable_successors(net, m, start) == frozenset(
        {
            marking(net, power="On", light="Dark", running=("cutter", "watcher")),
            marking(net, power="On", light="Green", running=("cutter",)),
        }
    )


def test_steps_lists_each_firable_transition_with_its_results(net: PetriNet) -> None:
    m = marking(net, running=("watcher", "red"))
    got = {t.id: results for t, results in steps(net, m)}
    assert list(got) == [
        "selfish.start", "night.start", "watcher.interrupt", "red.interrupt", "restorer.start", "cutter.start#2",
    ]  # fmt: skip
    assert got["selfish.start"] == frozenset({marking(net, mode="Busy", light="Red", running=("watcher", "red"))})
    assert got["watcher.interrupt"] == frozenset({marking(net, running=("red",))})
    assert got["cutter.start#2"] == frozenset(
        {
            marking(net, power="Off", light="Red", running=("cutter",)),
            marking(net, power="Off", light="Green", running=("cutter",)),
        }
    )


def test_priority_is_per_net_in_a_union() -> None:
    # An invariant enabled in one component does not block the other component.
    a = build_net(parse_skillset(CASCADE), eventless=True)
    b = build_net(parse_skillset("skillset b { skill k {} }"), eventless=True)
    u = union([a, b])
    assert u.places[-2:] == ("b:e_k", "b:i_k")
    transient = fire(tr(a, "selfish.start"), a.initial) | b.initial << len(a.places)
    assert ids(enabled(u, transient)) == ["c:selfish.inv.needs_idle", "b:k.start"]


# ---------------------------------------------------------------------------
# Random firing sequences on real nets: 1-safety and conservation


def _groups(ss: Skillset, prefix: str = "") -> list[list[str]]:
    """Place groups holding exactly one token: each resource's states, each skill's e/i."""
    groups = [[prefix + resource_place(r.name, s) for s in r.states] for r in ss.resources]
    groups += [[prefix + idle_place(k.name), prefix + running_place(k.name)] for k in ss.skills]
    return groups


CORPUS_FILES = ("spot.rl", "manipulator.rl", "isae_robot/isae_robot.rl")
Case = tuple[str, PetriNet, list[list[str]]]


@pytest.fixture(scope="session")
def cases(corpus_skillset, paper_skillset) -> list[Case]:
    """Full and eventless corpus nets, the paper's full nets and their eventless union."""
    cases = []
    for name in CORPUS_FILES:
        ss = corpus_skillset(name)
        cases.append((f"corpus/{name}", build_net(ss), _groups(ss)))
        cases.append((f"corpus/{name} eventless", build_net(ss, eventless=True), _groups(ss)))
    paper = [paper_skillset(name) for name in ("spot.rl", "manipulator.rl")]
    for ss in paper:
        cases.append((f"skillsets/{ss.name}", build_net(ss), _groups(ss)))
    union_net = union([build_net(ss, eventless=True) for ss in paper])
    cases.append(("skillsets union", union_net, [g for ss in paper for g in _groups(ss, f"{ss.name}:")]))
    return cases


def _check(net: PetriNet, groups: list[list[str]], m: int) -> None:
    for group in groups:
        marked = [p for p in group if m >> net.place_index(p) & 1]
        assert len(marked) == 1, (group, net.marked(m))
    assert sum(len(g) for g in groups) == len(net.places)  # no place outside a group


def _fire_checked(net: PetriNet, t: Transition, m: int) -> int:
    assert m & t.pre_mask == t.pre_mask
    # 1-safety: no token is produced on a place that keeps its token (self-loops excepted)
    assert (m & ~t.pre_mask) & t.post_mask == 0, (t.id, net.marked(m))
    return fire(t, m)


def test_hypothesis_cases_cover_the_corpus(cases: list[Case]) -> None:
    assert [c[0] for c in cases] == [
        "corpus/spot.rl", "corpus/spot.rl eventless",
        "corpus/manipulator.rl", "corpus/manipulator.rl eventless",
        "corpus/isae_robot/isae_robot.rl", "corpus/isae_robot/isae_robot.rl eventless",
        "skillsets/spot", "skillsets/manipulator", "skillsets union",
    ]  # fmt: skip
    for _, net, groups in cases:
        _check(net, groups, net.initial)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_random_runs_stay_one_safe(cases: list[Case], data) -> None:
    """Steps as the monitor sees them: a stable marking, one transition, its cascade."""
    _, net, groups = data.draw(st.sampled_from(cases), label="net")
    m = net.initial
    for _ in range(data.draw(st.integers(0, 60), label="length")):
        assert is_stable(net, m)
        on = enabled(net, m)
        if not on:
            break
        t = on[data.draw(st.integers(0, len(on) - 1), label=f"pick among {len(on)}")]
        assert not t.is_invariant
        results = stable_successors(net, m, t)
        m2 = _fire_checked(net, t, m)
        _check(net, groups, m2)
        if not is_stable(net, m2):
            event("invariant cascade")
        if len(results) > 1:
            event("several stable results")
        while not is_stable(net, m2):
            invs = enabled(net, m2)
            assert invs and all(i.is_invariant for i in invs)  # priority at transient markings
            inv = invs[data.draw(st.integers(0, len(invs) - 1), label="invariant")]
            m2 = _fire_checked(net, inv, m2)
            _check(net, groups, m2)
        assert m2 in results
        m = m2


@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_random_runs_ignoring_priority_stay_one_safe(cases: list[Case], data) -> None:
    """1-safety is structural: it holds even when priorities are ignored."""
    _, net, groups = data.draw(st.sampled_from(cases), label="net")
    m = net.initial
    for _ in range(data.draw(st.integers(0, 60), label="length")):
        on = [t for t in net.transitions if is_enabled(t, m)]
        if not on:
            break
        t = on[data.draw(st.integers(0, len(on) - 1), label="pick")]
        m = _fire_checked(net, t, m)
        _check(net, groups, m)
