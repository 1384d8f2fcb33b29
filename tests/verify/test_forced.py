"""Forced violations against a brute-force definition on the explicit product (docs/semantics.md §6.3).

The reference is the definition itself: breadth-first search over the product
of the components' *full* nets, one component step at a time, using only the
uncontrollable steps (skill outcomes, and events when asked); the least number
of steps to a marking violating the property is ``forced(...).steps``.  Random
systems are two random skillsets written as ``.rl`` text, so the whole chain
(parser, net builder, cascades, priorities) is exercised.
"""

from __future__ import annotations

from collections import deque
from functools import cache
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from skinet.system.load import load_system
from skinet.lang.parser import parse_skillset
from skinet.net.semantics import steps
from skinet.props.evaluate import holds
from skinet.props.formula import Property
from skinet.system.model import System, build_system
from skinet.verify.explore import explore
from skinet.verify.forced import forced, forced_mask, uncontrollable_kinds
from skinet.verify.predict import forecast

ROOT = Path(__file__).resolve().parents[2]
Combined = tuple[int, ...]
MAX_MARKINGS = 120  # product markings checked per random system


# --- random skillsets -----------------------------------------------------------------------


Resources = list[tuple[str, list[str]]]


def boolean(draw: st.DrawFn, leaf, depth: int = 2) -> str:
    """A random ``not``/``and``/``or`` combination of ``leaf()`` texts (plain draws: cheap to generate)."""
    op = draw(st.integers(0, 5)) if depth else 0
    if op <= 2:
        return leaf()
    if op == 3:
        return f"not ({boolean(draw, leaf, depth - 1)})"
    word = "and" if op == 4 else "or"
    return f"({boolean(draw, leaf, depth - 1)}) {word} ({boolean(draw, leaf, depth - 1)})"


def guard(draw: st.DrawFn, resources: Resources) -> str:
    """A guard over a skillset's own resources: ``==``, ``!=``, constants, not, and, or."""

    def leaf() -> str:
        r, states = draw(st.sampled_from(resources))
        return draw(st.sampled_from([f"{r} == {x}" for x in states] * 2 + [f"{r} != {x}" for x in states]
                                    + ["true", "false"]))

    return boolean(draw, leaf)


def effects(draw: st.DrawFn, resources: Resources, min_size: int = 0) -> str:
    chosen = [r for r in resources if draw(st.booleans())] or resources[:min_size]
    moves = " ".join(f"{r} -> {draw(st.sampled_from(states))}" for r, states in chosen)
    return f"{{ {moves} }}"


@st.composite
def skillset_texts(draw: st.DrawFn, name: str) -> str:
    """A random skillset: 1-2 resources of 2-3 states, an optional event, 1-3 skills."""
    resources: Resources = []
    lines = [f"skillset {name} {{", "resource {"]
    for r in range(draw(st.integers(1, 2))):
        states = [f"{x}{r}" for x in ("a", "b", "c")[: draw(st.integers(2, 3))]]
        resources.append((f"r{r}", states))
        pairs = [(a, b) for a in states for b in states if a != b]
        if draw(st.integers(0, 2)) > 0:
            transition = "transition all"
        else:
            chosen = [pair for pair in pairs if draw(st.booleans())] or pairs[:1]
            transition = "transition { " + " ".join(f"{a} -> {b}" for a, b in chosen) + " }"
        lines.append(f"r{r} {{ state {{ {' '.join(states)} }} initial {draw(st.sampled_from(states))} {transition} }}")
    lines.append("}")
    if draw(st.booleans()):
        r, states = draw(st.sampled_from(resources))
        lines.append(f"event {{ ev {{ guard {guard(draw, resources)} effect {r} -> {draw(st.sampled_from(states))} }} }}")
    for k in range(draw(st.integers(1, 3))):
        lines.append(f"skill k{k} {{")
        pre = [guard(draw, resources) for _ in range(draw(st.integers(0, 2)))]
        if pre:
            lines.append("precondition { " + " ".join(f"c{i}: {e}" for i, e in enumerate(pre)) + " }")
        if draw(st.booleans()):
            lines.append(f"start {effects(draw, resources, 1)}")
        if draw(st.integers(0, 3)) == 0:
            lines.append(f"invariant {{ j {{ guard {guard(draw, resources)} effect {effects(draw, resources)} }} }}")
        if draw(st.booleans()):
            lines.append(f"interrupt {{ interrupting true effect {effects(draw, resources)} }}")
        for kind, low in (("success", 1), ("failure", 0)):
            modes = []
            for i in range(draw(st.integers(low, 2))):
                post = f" postcondition {guard(draw, resources)}" if draw(st.integers(0, 3)) == 0 else ""
                modes.append(f"{kind[0]}{i} {{ effect {effects(draw, resources)}{post} }}")
            if modes:
                lines.append(f"{kind} {{ {' '.join(modes)} }}")
        lines.append("}")
    lines.append("}")
    return "\n".join(lines)


@st.composite
def random_systems(draw: st.DrawFn) -> System:
    """Two random skillsets and 1-3 properties over their places."""
    skillsets = [parse_skillset(draw(skillset_texts(n)), f"<{n}>") for n in ("s0", "s1")]
    atoms = [f"{ss.name}:{r.name}.{x}" for ss in skillsets for r in ss.resources for x in r.states]
    atoms += [f"{ss.name}:{p}_{k.name}" for ss in skillsets for k in ss.skills for p in ("i", "e")]

    def prop() -> str:  # mostly "not (a and b)", the shape of safety properties, so mostly true
        def atom() -> str:
            return draw(st.sampled_from(atoms))

        if draw(st.integers(0, 3)) == 0:
            return boolean(draw, atom, 3)
        return f"not (({boolean(draw, atom, 1)}) and ({boolean(draw, atom, 1)}))"

    props = "\n".join(f"p{i} = {prop()}" for i in range(draw(st.integers(1, 3))))
    return build_system("random", [(ss, "") for ss in skillsets], props)


def with_properties(system: System, properties: str) -> System:
    """The same skillsets with other properties (forced() knows a system's own properties only)."""
    return build_system(system.name, [(c.skillset, c.manager) for c in system.components], properties)


# --- brute force on the explicit product ----------------------------------------------------


class Product:
    """Product markings of a system's full nets, stepped one component at a time."""

    def __init__(self, system: System):
        self.system = system
        self.names = [c.name for c in system.components]
        self.nets = [c.net for c in system.components]

    def marking(self, m: Combined) -> dict[str, int]:
        return dict(zip(self.names, m))

    def violates(self, prop: Property, m: Combined) -> bool:
        return not holds(prop.expr, self.marking(m), self.system.nets)

    def successors(self, m: Combined, kinds: frozenset[str] | None = None) -> set[Combined]:
        """One step of one component (``kinds``: only those transition kinds)."""
        out = set()
        for i, net in enumerate(self.nets):
            for t, results in steps(net, m[i]):
                if kinds is None or t.kind in kinds:
                    out |= {m[:i] + (r,) + m[i + 1:] for r in results}
        return out

    def reachable(self, limit: int) -> list[Combined]:
        """The first ``limit`` markings reached from the initial one by any steps, breadth first."""
        root = tuple(net.initial for net in self.nets)
        order, seen = [root], {root}
        for m in order:
            if len(order) >= limit:
                break
            for n in sorted(self.successors(m)):
                if n not in seen:
                    seen.add(n)
                    order.append(n)
        return order[:limit]

    def forced_steps(self, prop: Property, m: Combined, events: bool) -> int | None:
        """Least number of uncontrollable steps from ``m`` to a violation (None: never)."""
        kinds = uncontrollable_kinds(events)
        dist = {m: 0}
        queue = deque([m])
        while queue:
            x = queue.popleft()
            if self.violates(prop, x):
                return dist[x]
            for n in self.successors(x, kinds):
                if n not in dist:
                    dist[n] = dist[x] + 1
                    queue.append(n)
        return None

    def replay(self, m: Combined, witness: tuple[str, ...], events: bool) -> set[Combined]:
        """Markings the witness can end in from ``m``; every label must be an uncontrollable firable step."""
        kinds = uncontrollable_kinds(events)
        current = {m}
        for n, label in enumerate(witness):
            skillset, name = label.split(":", 1)
            i = self.names.index(skillset)
            nxt = set()
            for x in current:
                for t, results in steps(self.nets[i], x[i]):
                    if t.name == name:
                        assert t.kind in kinds, (label, t.kind)
                        nxt |= {x[:i] + (r,) + x[i + 1:] for r in results}
            assert nxt, ("not firable", m, witness[: n + 1])
            current = nxt
        return current


def assert_forced_matches(ref: Product, prop: Property, m: Combined, events: bool) -> None:
    expected = ref.forced_steps(prop, m, events)
    verdict = forced(ref.system, ref.marking(m), prop, events)
    if expected is None:
        assert verdict is None, (prop.name, m, verdict)
        return
    assert verdict is not None and verdict.steps == expected, (prop.name, m, verdict, expected)
    assert len(verdict.witness) == expected
    reached = tuple(verdict.reached[n] for n in ref.names)
    assert ref.violates(prop, reached)
    assert reached in ref.replay(m, verdict.witness, events)


@settings(max_examples=70, deadline=None)
@given(system=random_systems(), events=st.booleans())
def test_forced_matches_brute_force(system: System, events: bool) -> None:
    ref = Product(system)
    for m in ref.reachable(MAX_MARKINGS):
        for prop in system.properties:
            assert_forced_matches(ref, prop, m, events)


@settings(max_examples=40, deadline=None)
@given(system=random_systems(), events=st.booleans())
def test_forced_mask_matches_brute_force(system: System, events: bool) -> None:
    space = explore(system)
    ref = Product(system)
    stored = np.flatnonzero(space.stored())
    for prop in system.properties:
        mask = forced_mask(system, space.components, space.local, prop, events)
        assert mask.shape == (space.box,)
        for code in stored[:MAX_MARKINGS]:
            m = tuple(space.marking(int(code))[n] for n in ref.names)
            assert bool(mask[code]) == (ref.forced_steps(prop, m, events) is not None), (prop.name, m)


@settings(max_examples=15, deadline=None)
@given(system=random_systems())
def test_constant_properties(system: System) -> None:
    """A property without atoms: never forced when true, forced in 0 steps everywhere when false."""
    system = with_properties(system, "ok = true\nbad = false\n")
    ok, bad = system.properties
    space = explore(system)
    m = system.initial_marking()
    assert forced(system, m, ok) is None
    verdict = forced(system, m, bad)
    assert verdict is not None and (verdict.steps, verdict.witness) == (0, ())
    assert not forced_mask(system, space.components, space.local, ok)[space.stored()].any()
    assert forced_mask(system, space.components, space.local, bad)[space.stored()].all()


# Two skills of `left` and one of `right` must all succeed, and `kick` (an event) can do right's part.
STEPS = {
    "left": """skillset left {
        resource { rx { state { lo hi } initial lo transition all } ry { state { lo hi } initial lo transition all } }
        skill x { success done { effect rx -> hi } failure stop {} }
        skill y { success done { effect ry -> hi } }
    }""",
    "right": """skillset right {
        resource { rz { state { lo hi } initial lo transition all } }
        event { kick { guard rz == lo effect rz -> hi } }
        skill z { success done { effect rz -> hi } }
    }""",
}


def test_steps_add_up_across_components() -> None:
    system = build_system("steps", [(parse_skillset(t, f"<{n}>"), "") for n, t in STEPS.items()],
                          "all_up = not (left:rx.hi and left:ry.hi and right:rz.hi)\n")
    prop, = system.properties
    left, right = system.component("left").net, system.component("right").net
    running = {"left": left.marking_of({"rx.lo", "ry.lo", "i_x", "i_y"}), "right": right.marking_of({"rz.lo", "i_z"})}
    verdict = forced(system, running, prop)
    assert verdict is not None and verdict.steps == 3
    assert sorted(verdict.witness) == ["left:x.success.done", "left:y.success.done", "right:z.success.done"]
    assert verdict.reached == {"left": left.marking_of({"rx.hi", "ry.hi", "e_x", "e_y"}),
                               "right": right.marking_of({"rz.hi", "e_z"})}
    ref = Product(system)
    m = (running["left"], running["right"])
    assert (verdict.reached["left"], verdict.reached["right"]) in ref.replay(m, verdict.witness, False)
    # z idle: only the event can raise rz.
    waiting = dict(running, right=right.marking_of({"rz.lo", "e_z"}))
    assert forced(system, waiting, prop) is None
    verdict = forced(system, waiting, prop, events=True)
    assert verdict is not None and verdict.steps == 3 and "right:kick" in verdict.witness
    # x may fail instead: still forced through its success, which is one possible outcome.
    only_y = dict(running, left=left.marking_of({"rx.hi", "ry.lo", "e_x", "i_y"}))
    verdict = forced(system, only_y, prop)
    assert verdict is not None and verdict.steps == 2


def test_reached_keeps_unmentioned_components() -> None:
    """`reached` is the combined marking at the end of the witness: a component the property does
    not mention does not move, so it keeps the marking it has in the query."""
    system = with_properties(mobile_manip(), "stopped = not base:Still\n")
    prop, = system.properties
    arm = system.component("arm").net
    undocking = base_marking("motion.Moving", "dock.Docked", "i_undock", "e_navigate", "e_dock_station")
    for arm_marking_now in (arm.initial, UNFOLDING["arm"]):
        verdict = forced(system, {"base": undocking, "arm": arm_marking_now}, prop)
        assert verdict is not None and verdict.steps == 1
        assert verdict.reached["arm"] == arm_marking_now


# --- the mobile manipulator example ---------------------------------------------------------


@cache
def mobile_manip() -> System:
    return load_system(ROOT / "skillsets" / "mobile_manip.toml")[0]


def base_marking(*places: str) -> int:
    return mobile_manip().component("base").net.marking_of({*places})


def arm_marking(*places: str) -> int:
    return mobile_manip().component("arm").net.marking_of({*places})


BASE_IDLE = ("e_undock", "e_navigate", "e_dock_station")
ARM_IDLE = ("e_unfold", "e_pick", "e_place", "e_fold")
UNFOLDING = {  # base undocked and still, unfold running (mutex Busy), arm still Folded
    "base": base_marking("motion.Still", "dock.Undocked", *BASE_IDLE),
    "arm": arm_marking("mutex.Busy", "pose.Folded", "i_unfold", "e_pick", "e_place", "e_fold"),
}


def fire(system: System, marking: dict[str, int], label: str) -> dict[str, int]:
    skillset, name = label.split(":", 1)
    net = system.component(skillset).net
    results = {r for t, rs in steps(net, marking[skillset]) if t.name == name for r in rs}
    assert len(results) == 1, (label, results)
    return dict(marking, **{skillset: results.pop()})


def test_navigate_while_unfolding_is_forced() -> None:
    """Starting navigate while unfold runs: unfold's success alone leaves the arm out while driving."""
    system = mobile_manip()
    stowed = system.property("stowed_drive")
    assert forced(system, UNFOLDING, stowed) is None  # nothing drives yet
    driving = fire(system, UNFOLDING, "base:navigate.start")
    for events in (False, True):
        verdict = forced(system, driving, stowed, events)
        assert verdict is not None
        assert (verdict.steps, verdict.witness) == (1, ("arm:unfold.success.unfolded",))
        assert verdict.reached == {
            "base": base_marking("motion.Moving", "dock.Undocked", "e_undock", "i_navigate", "e_dock_station"),
            "arm": arm_marking("mutex.Free", "pose.Unfolded", *ARM_IDLE),
        }
    assert forced(system, driving, system.property("still_grasp")) is None
    # Once unfold has ended, the violation is explicit: 0 steps, no witness.
    unfolded = fire(system, driving, "arm:unfold.success.unfolded")
    verdict = forced(system, unfolded, stowed)
    assert verdict is not None and (verdict.steps, verdict.witness) == (0, ())
    # Had navigate ended first, nothing uncontrollable would be left to violate.
    arrived = fire(system, driving, "base:navigate.success.arrived")
    assert forced(system, arrived, stowed) is None


def test_mobile_manip_forced_everywhere() -> None:
    """Every marking reachable in the product of the full nets, both properties, both options."""
    system = mobile_manip()
    ref = Product(system)
    markings = ref.reachable(10_000)
    assert len(markings) == 35
    counts = {}
    for prop in system.properties:
        for events in (False, True):
            for m in markings:
                assert_forced_matches(ref, prop, m, events)
            counts[prop.name, events] = sum(forced(system, ref.marking(m), prop, events) is not None
                                            for m in markings)
    assert counts == {("stowed_drive", False): 12, ("stowed_drive", True): 12,
                      ("still_grasp", False): 6, ("still_grasp", True): 6}
    fc = forecast(system, full=True)
    for prop in system.properties:
        assert np.array_equal(fc.risks[prop.name].forced,
                              forced_mask(system, fc.space.components, fc.space.local, prop))


def test_bumper_hit_changes_no_forced_verdict() -> None:
    """bumper_hit stops the wheels and in_motion then stops the skill: the same marking a failure
    outcome leads to, so counting events as uncontrollable never changes a verdict's steps on
    this system, for any property; it only offers another shortest witness."""
    system = mobile_manip()
    ref = Product(system)
    base = system.component("base").net
    for m in ref.reachable(10_000):
        hit = {r for t, rs in steps(base, m[0]) if t.kind == "event" for r in rs}
        outcomes = {r for t, rs in steps(base, m[0]) if t.kind == "failure" for r in rs}
        assert hit <= outcomes
        assert bool(hit) == bool(outcomes)
    system = with_properties(system, "stopped = not base:Still\n")
    stopped, = system.properties
    undocking = {"base": base_marking("motion.Moving", "dock.Docked", "i_undock", "e_navigate", "e_dock_station"),
                 "arm": system.component("arm").net.initial}
    assert holds(stopped.expr, undocking, system.nets)
    verdicts = {events: forced(system, undocking, stopped, events) for events in (False, True)}
    assert verdicts[False] is not None and verdicts[True] is not None
    assert verdicts[False].steps == verdicts[True].steps == 1
    assert verdicts[False].witness[0] in {"base:undock.success.undocked", "base:undock.failure.stuck"}
    assert verdicts[True].witness[0] in {"base:bumper_hit", "base:undock.success.undocked",
                                         "base:undock.failure.stuck"}
    for events, verdict in verdicts.items():
        m = tuple(undocking[n] for n in ref.names)
        assert tuple(verdict.reached[n] for n in ref.names) in ref.replay(m, verdict.witness, events)
