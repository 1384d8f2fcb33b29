"""docs/mission.md acceptance: both paper runs through the whole chain.

Simulated managers (real CDR on bridge keys) -> bridge_ros2 -> monitor ->
predictor, on one embedded Zenoh session; the records must equal the core
replay step for step and show exactly the paper's violations and warnings.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from chains.chain import run_chain
from skinet.system.load import load_system, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import StepRecord, parse_scenario, replay

MISSIONS = Path(__file__).resolve().parents[2] / "skillsets" / "missions"


def both(name: str) -> tuple[list[StepRecord], list[StepRecord]]:
    scenario = parse_scenario(read_text(MISSIONS / f"{name}.toml"), name)
    system, _ = load_system(MISSIONS / scenario.system)
    return run_chain(system, load_typemap(MISSIONS / scenario.system), scenario), replay(system, scenario)


def comparable(records: list[StepRecord]) -> list[tuple]:
    def flags(us: list) -> list[tuple]:
        return [(u.skillset, u.transition, u.property, u.constraint, u.steps, u.witness, u.reason) for u in us]

    return [(r.index, r.holds, r.violations, flags(r.warnings), flags(r.flagged), r.recovery, r.unsafe_count,
             r.divergence) for r in records]


def test_unassisted_run_through_the_chain() -> None:
    chain, core = both("unassisted")
    assert [(r.index, r.step.transition, r.violations) for r in chain if r.violations] == [
        (26, "teleop.start", ["action_guard"]),
        (33, "go_to_waypoint.start", ["safety_guard"]),
        (38, "arm_ready.start", ["action_guard"]),
    ]
    assert comparable(chain) == comparable(core)


def test_assisted_run_through_the_chain() -> None:
    chain, core = both("assisted")
    assert not any(r.violations for r in chain)
    assert [(r.index, [(w.transition, w.property, w.constraint, w.controllable) for w in r.warnings])
            for r in chain if r.step.consider] == [
        (29, [("go_to_waypoint.start", "safety_guard", "explicit", True)]),
        (36, [("arm_ready.start", "action_guard", "explicit", True)]),  # considered before step 36
    ]
    assert comparable(chain) == comparable(core)


def test_step_numbers_are_the_monitors(monkeypatch: pytest.MonkeyPatch) -> None:
    """A record's step number is the monitor's step (LiveState.seq) after it, as `skinet run` shows it:
    the bridge's start-up statuses are no steps, and a considered command is no step."""
    import chains.chain

    seen: list[tuple[int, int, bool]] = []
    record = chains.chain._record

    def spy(run, view, *rest):
        seen.append((run.index, view.state.seq, run.step.consider is not None))
        return record(run, view, *rest)

    monkeypatch.setattr(chains.chain, "_record", spy)
    scenario = parse_scenario(read_text(MISSIONS / "assisted.toml"), "assisted")
    system, _ = load_system(MISSIONS / scenario.system)
    run_chain(system, load_typemap(MISSIONS / scenario.system), scenario, predict=False)
    assert [i for i, _, considered in seen if considered] == [29, 36]
    assert [(i, seq) for i, seq, considered in seen if not considered] == [(i, i) for i in range(1, 61)]
    assert [(i, seq) for i, seq, considered in seen if considered] == [(29, 28), (36, 35)]  # before the step


def test_demo_command_runs_the_chain(capsys: pytest.CaptureFixture[str]) -> None:
    from skinet_cli.main import main

    assert main(["demo", "--all-steps"]) == 0
    out = capsys.readouterr().out
    assert out.count("chain: simulated managers -> CDR -> bridge -> monitor -> predictor") == 4
    assert "   violations: 3; action_guard at step 26; safety_guard at step 33; action_guard at step 38" in out
    assert "model divergence" not in out
    # The third run: the pilot (tests/services/test_pilot_demo.py), then every run side by side.
    assert out.count("   chain: simulated managers (skills end by themselves) -> CDR -> bridge -> monitor -> predictor "
                     "-> pilot -> check (strict) -> requests on the managers' topics") == 1
    assert out.endswith("== the runs side by side\n"
                        "   run                commands  moves  retries  violations  denied\n"
                        "   unassisted               31     62        0           3       -\n"
                        "   assisted                 30     60        0           0       -\n"
                        "   pilot                    34     68        2           0       0\n"
                        "   mobile unassisted         7     14        0           1       -\n"
                        "   mobile assisted           7     14        0           0       -\n")


def test_mobile_runs_through_the_chain() -> None:
    """The forced warning comes from the monitor itself, through the whole chain, as in the core replay."""
    chain, core = both("mobile_unassisted")
    assert [(r.index, r.violations) for r in chain if r.violations] == [(5, ["stowed_drive"])]
    assert [(u.transition, u.constraint, u.steps, u.witness) for u in chain[3].flagged] == [
        ("navigate.start", "forced", 1, ("arm:unfold.success.unfolded",))]
    assert comparable(chain) == comparable(core)
    chain, core = both("mobile_assisted")
    assert not any(r.violations for r in chain)
    assert comparable(chain) == comparable(core)


# -- steps the model does not allow (issue 27, item 3) -----------------------------------------

MOBILE = MISSIONS.parent / "mobile_manip.toml"
# Refused by the managers as real ones would: precondition, guard, already running, pick not running.
REFUSED = [("arm", "pick.start"), ("base", "bumper_hit"), ("arm", "unfold.start"), ("arm", "unfold.start"),
           ("arm", "unfold.interrupt"), ("arm", "pick.success.picked")]
DIVERGING = [1, 2, 4, 6]


def refused_scenario(marked: set[int] = frozenset()) -> str:
    """A scenario of :data:`REFUSED` whose steps ``marked`` (1-based) say ``expect_divergence = true``."""
    steps = "".join(f'\n[[steps]]\nskillset = "{s}"\ntransition = "{t}"\n'
                    + ("expect_divergence = true\n" if n in marked else "")
                    for n, (s, t) in enumerate(REFUSED, 1))
    return f'[scenario]\nname = "refused"\nsystem = "{MOBILE}"\n{steps}'


def test_steps_the_model_does_not_allow_are_divergences_in_the_chain_as_in_the_core() -> None:
    """The monitor sees nothing happen (the managers refuse): the chain shows the core's divergences anyway."""
    scenario = parse_scenario(refused_scenario(), "refused.toml")
    system, _ = load_system(MOBILE)
    chain = run_chain(system, load_typemap(MOBILE), scenario)
    assert [(r.index, r.divergence) for r in chain if r.divergence] == [
        (i, f"'{REFUSED[i - 1][1]}' is not enabled in the live marking") for i in DIVERGING]
    assert comparable(chain) == comparable(replay(system, scenario))


def test_mobile_divergence_mission_diverges_where_it_says(capsys: pytest.CaptureFixture[str]) -> None:
    from skinet_cli.main import main

    assert main(["demo", str(MISSIONS / "mobile_divergence.toml")]) == 0
    out, err = capsys.readouterr()
    assert "             model divergence: 'pick.success.picked' is not enabled in the live marking\n" in out
    assert "   divergences: 1; arm:pick.success.picked at step 3 (expected)\n" in out
    assert "skinet demo:" not in err


@pytest.mark.parametrize("core", [False, True], ids=["chain", "core"])
def test_demo_exit_status_says_whether_divergences_were_expected(tmp_path: Path, core: bool,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from skinet_cli.main import main

    def demo(marked: set[int]) -> tuple[int, str, list[str]]:
        path.write_text(refused_scenario(marked))
        code = main(["demo", *(["--core"] if core else []), str(path)])
        out, err = capsys.readouterr()
        return code, out, [line for line in err.splitlines() if line.startswith("skinet demo:")]

    path = tmp_path / "refused.toml"
    code, out, err = demo(set())
    assert code == 3
    assert ("   divergences: 4; arm:pick.start at step 1 (NOT EXPECTED); base:bumper_hit at step 2 (NOT EXPECTED); "
            "arm:unfold.start at step 4 (NOT EXPECTED); arm:pick.success.picked at step 6 (NOT EXPECTED)\n") in out
    assert err == [f"skinet demo: {path}: step {i} ({':'.join(REFUSED[i - 1])} at t=0 s): model divergence the "
                   f"scenario does not expect (mark it expect_divergence = true): '{REFUSED[i - 1][1]}' is not "
                   "enabled in the live marking" for i in DIVERGING]
    code, out, err = demo(set(DIVERGING))
    assert (code, err) == (0, [])
    assert ("   divergences: 4; arm:pick.start at step 1 (expected); base:bumper_hit at step 2 (expected); "
            "arm:unfold.start at step 4 (expected); arm:pick.success.picked at step 6 (expected)\n") in out
    code, out, err = demo({1, 2, 3, 4, 6})  # step 3 (a real start) marked: it did not diverge
    assert (code, err) == (3, [f"skinet demo: {path}: step 3 (arm:unfold.start at t=0 s): expected a model "
                               "divergence, none happened"])
