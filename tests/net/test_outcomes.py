"""Missed outcomes inferred from the markings before and after a gap (docs/how-it-works.md, *Missed outcomes*)."""

from __future__ import annotations

from skinet.lang.parser import parse_skillset
from skinet.net.build import build_net, idle_place, resource_place, running_place
from skinet.net.outcomes import MAX_SKILLS, infer_outcomes, modes
from skinet.net.semantics import stable_successors
from skinet.system.model import System, marking_from_json


def _marking(system: System, skillset: str, resources: dict[str, str], running: list[str]) -> int:
    return marking_from_json(system, {skillset: {"resources": resources, "running": running}})[skillset]


def test_a_mode_whose_postcondition_shows_is_inferred(paper_system: System) -> None:
    spot = paper_system.component("spot")
    before = _marking(paper_system, "spot", {"control_mode": "Busy"}, ["init_power"])
    on = _marking(paper_system, "spot", {"control_mode": "Idle", "power_status": "PowerOn"}, [])
    off = _marking(paper_system, "spot", {"control_mode": "Idle", "power_status": "PowerOff"}, [])
    [inferred] = infer_outcomes(spot.net, before, on, ["init_power"])
    assert (inferred.outcome, inferred.candidates) == ("init_power.success.powered_on", ("init_power.success.powered_on",))
    [inferred] = infer_outcomes(spot.net, before, off, ["init_power"])
    assert (inferred.outcome, inferred.candidates) == ("init_power.failure.no_battery",
                                                       ("init_power.failure.no_battery",))


def test_modes_with_the_same_effects_stay_unknown(paper_system: System) -> None:
    """teleop's success and failure both only free control_mode: the model cannot tell them apart."""
    spot = paper_system.component("spot")
    assert modes(spot.net, "teleop") == ("teleop.success.done", "teleop.failure.link_lost")
    before = _marking(paper_system, "spot", {"control_mode": "Busy", "power_status": "PowerOn",
                                             "posture": "Standing"}, ["teleop"])
    after = _marking(paper_system, "spot", {"control_mode": "Idle", "power_status": "PowerOn",
                                            "posture": "Standing"}, [])
    [inferred] = infer_outcomes(spot.net, before, after, ["teleop"])
    assert inferred.outcome is None
    assert inferred.candidates == ("teleop.success.done", "teleop.failure.link_lost")


def test_an_observation_no_mode_explains_has_no_candidate(paper_system: System) -> None:
    spot = paper_system.component("spot")
    before = _marking(paper_system, "spot", {"control_mode": "Busy"}, ["init_power"])
    sitting_busy = _marking(paper_system, "spot", {"control_mode": "Busy"}, [])
    [inferred] = infer_outcomes(spot.net, before, sitting_busy, ["init_power"])
    assert (inferred.outcome, inferred.candidates) == (None, ())


def test_every_single_mode_of_the_paper_system_is_told_apart_exactly_when_its_result_is(paper_system: System) -> None:
    """From every reachable marking with a skill running, each mode's results are inferred as that mode when no
    other mode of the skill can give the same marking, and left unknown (both candidates listed) when one can."""
    checked = ambiguous = 0
    for comp in paper_system.components:
        net = comp.net
        seen, todo = {net.initial}, [net.initial]
        while todo:
            m = todo.pop()
            for t in net.transitions:
                for n in (stable_successors(net, m, t) if (m & t.pre_mask) == t.pre_mask else ()):
                    if n not in seen:
                        seen.add(n)
                        todo.append(n)
        for m in seen:
            for skill in comp.skillset.skills:
                if not m >> net.place_index(running_place(skill.name)) & 1:
                    continue
                results = {name: set() for name in modes(net, skill.name)}
                for t in net.transitions:
                    if t.name in results and (m & t.pre_mask) == t.pre_mask:
                        results[t.name] |= stable_successors(net, m, t)
                for name, after in results.items():
                    for a in after:
                        [inf] = infer_outcomes(net, m, a, [skill.name])
                        others = [o for o, r in results.items() if a in r]
                        assert inf.candidates == tuple(others)
                        assert inf.outcome == (name if others == [name] else None)
                        checked += 1
                        ambiguous += len(others) > 1
    assert checked > 0 and 0 < ambiguous < checked


TWO = """
skillset two {
    resource {
        p { state { Off On } initial Off transition all }
        q { state { Down Up } initial Down transition all }
    }
    skill a { success on { postcondition p == On } failure off { } }
    skill b { success up { postcondition q == Up } failure down { } }
    skill c { success done { } failure lost { } }
}
"""


def test_several_missed_skills_of_one_skillset_are_taken_together() -> None:
    net = build_net(parse_skillset(TWO, "two.rl"))

    def m(p: str, q: str, *running: str) -> int:
        return net.marking_of([resource_place("p", p), resource_place("q", q)]
                              + [running_place(k) if k in running else idle_place(k) for k in "abc"])

    got = infer_outcomes(net, m("Off", "Down", "a", "b", "c"), m("On", "Down"), ["a", "b", "c"])
    assert [(i.skill, i.outcome, i.candidates) for i in got] == [
        ("a", "a.success.on", ("a.success.on",)),
        ("b", "b.failure.down", ("b.failure.down",)),
        ("c", None, ("c.success.done", "c.failure.lost")),
    ]
    # One skill still running: the observation cannot be the end of all three.
    got = infer_outcomes(net, m("Off", "Down", "a", "b"), m("On", "Down", "b"), ["a", "b"])
    assert [(i.outcome, i.candidates) for i in got] == [(None, ()), (None, ())]
    # Beyond MAX_SKILLS at once: unknown, never a guess.
    assert MAX_SKILLS == 4
    many = infer_outcomes(net, m("Off", "Down", "a", "b"), m("On", "Up"), ["a", "b", "c", "x", "y"])
    assert all(i.outcome is None and i.candidates == () for i in many)
