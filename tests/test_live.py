"""Following the live marking, and model divergence (docs/semantics.md §7)."""

from __future__ import annotations

from pathlib import Path

from skinet.system.load import load_system
from skinet.system.live import LiveSystem, Outcome
from skinet.system.model import marking_to_json

SYSTEM = Path(__file__).resolve().parents[1] / "skillsets" / "spot_arm.toml"


def live() -> LiveSystem:
    return LiveSystem(load_system(SYSTEM)[0])


def spot(l: LiveSystem) -> dict:
    return marking_to_json(l.system, l.marking)["spot"]


def test_transitions_advance_the_marking() -> None:
    l = live()
    assert l.apply("spot", "init_power.start") == Outcome("spot", "init_power.start", True)
    assert spot(l) == {"resources": {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Busy"},
                       "running": ["init_power"]}
    l.apply("spot", "init_power.success.powered_on")
    assert spot(l)["resources"]["power_status"] == "PowerOn"


def test_event_with_invariant_cascade() -> None:
    l = live()
    for t in ("init_power.start", "init_power.success.powered_on", "stand_up.start", "stand_up.success.standing",
              "teleop.start"):
        l.apply("spot", t)
    # power_switchoff violates teleop's invariants: the skill stops in the same step.
    assert l.apply("spot", "power_switchoff") == Outcome("spot", "power_switchoff", True)
    assert spot(l) == {"resources": {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"},
                       "running": []}


def test_not_enabled_keeps_the_marking() -> None:
    l = live()
    before = dict(l.marking)
    assert l.apply("spot", "teleop.start") == Outcome(
        "spot", "teleop.start", False, "'teleop.start' is not enabled in the live marking")
    assert l.marking == before


def test_observed_status_selects_or_diverges() -> None:
    l = live()
    observed = {"resources": {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Busy"},
                "running": ["init_power"]}
    assert l.apply("spot", None, observed) == Outcome("spot", None, True)  # explained by init_power.start
    odd = {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Idle"}, "running": []}
    out = l.apply("spot", "init_power.success.powered_on", odd)
    assert out == Outcome("spot", "init_power.success.powered_on", True,
                          "no transition explains the observed status of 'spot'; observed marking adopted")
    assert spot(l) == odd


def test_unknown_names_are_reported() -> None:
    l = live()
    assert l.apply("arm", "x").divergence == "unknown skillset 'arm' (skillsets: spot, manipulator)"
    assert l.apply("spot", "fly.start").divergence == "unknown transition 'fly.start' of 'spot'"
    bad = l.apply("spot", None, {"resources": {"posture": "Flying"}})
    assert bad.divergence == "unreadable status: unknown state 'Flying' of resource 'spot:posture' (states: Sitting, Standing)"
