"""The ``skinet`` command line: outputs, exit codes and error messages."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from skinet_cli.main import LAZY_COMMANDS, build_parser, main

ROOT = Path(__file__).resolve().parents[2]
SYSTEM = str(ROOT / "skillsets" / "spot_arm.toml")
CORPUS = ROOT.parent / "shared" / "corpus"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def state(tmp_path: Path, data: object) -> str:
    path = tmp_path / "state.json"
    path.write_text(json.dumps(data))
    return str(path)


def test_parse_summary(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "parse", str(CORPUS / "manipulator.rl"))
    assert code == 0 and err == ""
    assert out.splitlines()[1:3] == ["  resources (2):", "    arm_status: Hp Motion Static (initial Hp)"]
    assert "  skills (5): arm_moving_manual arm_moving_goaldriven arm_moving_interaction arm_moving_pickplace arm_moving_to_HP" in out


def test_parse_json(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "parse", str(CORPUS / "isae_robot" / "isae_robot.rl"), "--json")
    data = json.loads(out)
    assert code == 0
    assert data[0]["events"] == ["estop", "battery_to_low", "battery_to_ok"]
    assert data[0]["resources"]["battery_status"] == {"states": ["BatteryOk", "BatteryLow"], "initial": "BatteryOk"}


def test_parse_error_has_position_and_no_traceback(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    bad = tmp_path / "bad.rl"
    bad.write_text("skillset s {\n  resource r { state { A B } initial C transition all }\n}\n")
    code, out, err = run(capsys, "parse", str(bad))
    assert code == 1 and out == ""
    assert err == f"{bad}:2:38: error: initial state 'C' of resource 'r' is not declared\n"


def test_missing_file(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "parse", "no/such.rl")
    assert code == 1
    assert err == "no/such.rl: error: cannot read file: No such file or directory\n"


def test_net_tina_has_priorities(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "net", str(ROOT / "skillsets" / "spot.rl"), "--format", "tina")
    assert code == 0
    assert out.startswith("net spot\n")
    assert sum(line.startswith("pr ") for line in out.splitlines()) == 1
    assert "tr {go_to_waypoint.start} : {go_to_waypoint.start}" in out


def test_net_eventless_json_to_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    target = tmp_path / "net.json"
    code, out, _ = run(capsys, "net", str(ROOT / "skillsets" / "spot.rl"), "--eventless", "-o", str(target))
    data = json.loads(target.read_text())
    assert code == 0 and out == ""
    assert all(t["kind"] != "event" for t in data["transitions"])
    assert len(data["places"]) == 18


def test_unsafe_initial_marking(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "unsafe", SYSTEM)
    assert code == 0
    assert "properties: action_guard holds, safety_guard holds" in out
    assert "unsafe transitions (0):" in out
    assert "prediction: complete, 63 markings" in out


def test_unsafe_paper_warning_safety_guard(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    s = state(tmp_path, {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing"}},
                         "manipulator": {"resources": {"arm_status": "RD"}}})
    code, out, _ = run(capsys, "unsafe", SYSTEM, "--state", s, "--json")
    data = json.loads(out)
    assert code == 0
    assert data["unsafe"] == [{
        "skillset": "spot", "transition": "go_to_waypoint.start", "kind": "start", "controllable": True,
        "property": "safety_guard", "constraint": "explicit", "steps": 0, "witness": [],
        "reason": "violates it at once: spot go_to_waypoint runs while manipulator arm_status at RD",
    }]
    assert data["prediction"]["complete"] is True


def test_unsafe_paper_warning_action_guard(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    s = state(tmp_path, {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing",
                                                "control_mode": "Busy"}, "running": ["teleop"]}})
    code, out, _ = run(capsys, "unsafe", SYSTEM, "--state", s, "--no-predict")
    assert code == 0
    assert "  manipulator  arm_ready.start  action_guard  explicit    controllable  0" in out
    assert "prediction: off (explicit constraints only)" in out


def test_unsafe_violated_now_lists_recovery(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    s = state(tmp_path, {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing",
                                                "control_mode": "Busy"}, "running": ["teleop"]},
                         "manipulator": {"resources": {"mutex": "Busy", "arm_status": "Moving"}, "running": ["arm_ready"]}})
    code, out, _ = run(capsys, "unsafe", SYSTEM, "--state", s)
    assert code == 0
    assert "properties: action_guard VIOLATED, safety_guard holds" in out
    assert ("action_guard is violated now; recovery transitions: spot:power_switchoff, spot:teleop.interrupt, spot:teleop.success.done, "
            "spot:teleop.failure.link_lost, manipulator:arm_emergency_stop, manipulator:arm_ready.interrupt, manipulator:arm_ready.success.ready, "
            "manipulator:arm_ready.failure.blocked") in out



# safety_guard violated: Spot walks while the arm is at RD.
WALKING_ARM_AT_RD = {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"},
                              "running": ["go_to_waypoint"]},
                     "manipulator": {"resources": {"arm_status": "RD"}}}


def test_literal_list_keeps_violated_properties(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    s = state(tmp_path, WALKING_ARM_AT_RD)
    _, operator, _ = run(capsys, "unsafe", SYSTEM, "--state", s, "--json")
    _, both, _ = run(capsys, "unsafe", SYSTEM, "--state", s, "--literal", "--json")
    shown = lambda items: [(u["property"], u["transition"]) for u in items]  # noqa: E731
    assert "literal" not in json.loads(operator)
    assert shown(json.loads(operator)["unsafe"]) == [("action_guard", "arm_joystick.start"),
                                                     ("action_guard", "arm_RD_to_HP.start")]
    # --literal adds the literal list to the operator view (its help says "also"), replacing nothing.
    assert json.loads(both)["unsafe"] == json.loads(operator)["unsafe"]
    assert json.loads(both)["recovery"] == json.loads(operator)["recovery"]
    assert shown(json.loads(both)["literal"]) == [
        ("action_guard", "arm_joystick.start"), ("safety_guard", "arm_joystick.start"),
        ("action_guard", "arm_RD_to_HP.start"), ("safety_guard", "arm_RD_to_HP.start"),
    ]


def test_literal_text_keeps_the_operator_view(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    s = state(tmp_path, WALKING_ARM_AT_RD)
    _, operator, _ = run(capsys, "unsafe", SYSTEM, "--state", s, "--no-predict")
    _, both, _ = run(capsys, "unsafe", SYSTEM, "--state", s, "--no-predict", "--literal")
    view = operator.splitlines()[:-1]  # without the "prediction: off" line
    assert both.splitlines()[:len(view)] == view
    assert "safety_guard is violated now; recovery transitions: spot:power_switchoff," in operator
    assert both.splitlines()[len(view)] == "literal Algorithm 1 (also for properties already violated) (4):"
    assert "  manipulator  arm_joystick.start  safety_guard  explicit    controllable  0" in both.splitlines()


def test_state_errors(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    s = state(tmp_path, {"spot": {"resources": {"posture": "Flying"}}})
    code, _, err = run(capsys, "unsafe", SYSTEM, "--state", s)
    assert code == 1
    assert err == f"{s}: error: unknown state 'Flying' of resource 'spot:posture' (states: Sitting, Standing)\n"
    bad = tmp_path / "bad.json"
    bad.write_text('{"spot": ')
    code, _, err = run(capsys, "unsafe", SYSTEM, "--state", str(bad))
    assert err == f"{bad}:1:10: error: invalid JSON: Expecting value\n"


def test_system_file_errors(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    sysfile = tmp_path / "s.toml"
    sysfile.write_text("[system]\nname = \n")
    code, _, err = run(capsys, "explore", str(sysfile))
    assert code == 1
    assert err == f"{sysfile}:2:8: error: invalid TOML: Invalid value\n"
    sysfile.write_text('[system]\nname = "x"\n')
    code, _, err = run(capsys, "explore", str(sysfile))
    assert err == f"{sysfile}: error: missing [[skillsets]] entries (each with 'model' and 'manager')\n"


def test_bad_property_reports_candidates(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    for name in ("spot.rl", "manipulator.rl"):
        (tmp_path / name).write_text((ROOT / "skillsets" / name).read_text())
    (tmp_path / "p.props").write_text("g = not spot:Bussy\n")
    (tmp_path / "s.toml").write_text(
        '[system]\nname = "x"\nproperties = "p.props"\n[[skillsets]]\nmodel = "spot.rl"\n[[skillsets]]\nmodel = "manipulator.rl"\n'
    )
    code, _, err = run(capsys, "unsafe", str(tmp_path / "s.toml"))
    assert code == 1
    assert err == f"{tmp_path / 'p.props'}:1:9: error: unknown name 'spot:Bussy' (candidates: spot:Busy)\n"


def test_explore_report(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "explore", SYSTEM, "--json")
    data = json.loads(out)
    assert code == 0
    assert (data["complete"], data["markings"], data["edges"], data["deadlocks"]) == (True, 63, 220, 0)
    assert data["properties"]["action_guard"] == {
        "violating": 24, "dangerous": 24, "undecided": 0, "safe": 39, "implicit_fair": 0, "undecided_fair": 0,
        "implicit_literal": 0, "undecided_literal": 0, "forced": 0}
    assert data["af"] == {"action_guard": "fair", "safety_guard": "fair"}
    assert data["properties"]["safety_guard"] == {
        "violating": 6, "dangerous": 6, "undecided": 0, "safe": 57, "implicit_fair": 0, "undecided_fair": 0,
        "implicit_literal": 0, "undecided_literal": 0, "forced": 0}


def test_explore_truncated(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "explore", SYSTEM, "--max-depth", "2", "--json")
    data = json.loads(out)
    assert (data["complete"], data["depth"]) == (False, 1)
    assert data["frontier"] > 0 and data["properties"]["action_guard"]["undecided"] > 0


def test_ctl(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "ctl", SYSTEM, "EF (spot:Busy and manipulator:Busy)")
    assert code == 0
    assert out.splitlines()[1:] == ["satisfied by 63 of 63 markings", "at the start marking: holds"]
    code, out, _ = run(capsys, "ctl", SYSTEM, "AG not (spot:Busy and manipulator:Busy)", "--json")
    (data,) = json.loads(out)
    assert (data["formula"], data["satisfying"], data["start"]) == ("AG not (spot:Busy and manipulator:Busy)", 0, "fails")


def test_ctl_several_formulas_share_one_exploration(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "ctl", SYSTEM, "AG not spot:i_go_to_waypoint", "EF spot:Busy", "--json")
    assert code == 0
    assert [(d["formula"], d["satisfying"], d["markings"], d["start"]) for d in json.loads(out)] == [
        ("AG not spot:i_go_to_waypoint", 0, 63, "fails"), ("EF spot:Busy", 63, 63, "holds")]
    code, out, _ = run(capsys, "ctl", SYSTEM, "EF spot:Busy", "AG not spot:i_go_to_waypoint")
    assert out.splitlines() == ["formula: EF spot:Busy", "satisfied by 63 of 63 markings", "at the start marking: holds",
                                "", "formula: AG not spot:i_go_to_waypoint", "satisfied by 0 of 63 markings",
                                "at the start marking: fails"]
    code, _, err = run(capsys, "ctl", SYSTEM, "EF spot:Busy", "AG (spot:Busy")
    assert code == 1 and err.startswith("<formula 2>:1:14: error: unexpected end of input")


def test_ctl_cut_by_the_budget_says_what_was_explored(capsys: pytest.CaptureFixture[str]) -> None:
    """What needs no exploration is answered; the rest is undecided; the last line says what was explored."""
    code, out, _ = run(capsys, "ctl", SYSTEM, "AG true", "AG AG AG AG AG AG AG AG not spot:Busy", "EF false",
                       "--budget", "0.000001")
    assert code == 0
    assert out.splitlines() == [
        "formula: AG true", "satisfied by 1 of 1 markings", "at the start marking: holds", "",
        "formula: AG AG AG AG AG AG AG AG not spot:Busy", "satisfied by 0 of 1 markings (1 undecided)",
        "at the start marking: undecided", "",
        "formula: EF false", "satisfied by 0 of 1 markings", "at the start marking: fails",
        "truncated by budget (only the live marking stored, no layer expanded): answers are three-valued"]
    code, out, _ = run(capsys, "ctl", SYSTEM, "AG not spot:i_go_to_waypoint", "--max-depth", "2")
    assert out.splitlines()[-1] == ("truncated by depth (depths 0 to 1 expanded, 7 markings stored): "
                                    "answers are three-valued")
    code, out, _ = run(capsys, "explore", SYSTEM, "--max-depth", "1")
    assert "  complete   no (truncated by depth: depth 0 expanded, 3 markings stored)" in out.splitlines()


def test_ctl_syntax_error(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "ctl", SYSTEM, "AG (spot:Busy")
    assert code == 1
    assert err.startswith("<formula>:1:14: error: unexpected end of input, expected one of: ')'")


def test_demo_reproduces_the_paper(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "demo")
    assert code == 0
    assert "   violations: 3; action_guard at step 26; safety_guard at step 33; action_guard at step 38" in out
    assert ("     safety_guard at step 33: SkiNet flagged spot:go_to_waypoint.start when it was issued at step 33 "
            "(explicit, the command itself); the operator went ahead") in out
    assert ("   warnings heeded (commands considered, flagged, not issued): 2; spot:go_to_waypoint.start explicit for "
            "safety_guard at step 29; manipulator:arm_ready.start explicit for action_guard at step 36") in out
    assert "   violations: 0" in out
    assert "   violations: 1; stowed_drive at step 5" in out  # the mobile manipulator after the paper's runs


def test_prediction_options_from_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    state = str(ROOT / "skillsets" / "states" / "unfolding.json")
    system = str(ROOT / "skillsets" / "mobile_manip.toml")
    code, out, _ = run(capsys, "unsafe", system, "--state", state)
    assert code == 0
    assert ("  base:navigate.start: forced for stowed_drive — unfold may succeed (1 step) and leave arm pose at "
            "Unfolded while base navigate runs") in out.splitlines()
    code, out, _ = run(capsys, "unsafe", system, "--state", state, "--no-forced")
    assert code == 0 and "unsafe transitions (0):" in out
    code, out, _ = run(capsys, "unsafe", system, "--state", state, "--af", "literal", "--json")
    data = json.loads(out)
    assert {o["af"] for o in data["options"].values()} == {"literal"}
    assert [(u["transition"], u["constraint"], u["steps"], u["witness"]) for u in data["unsafe"]] == [
        ("navigate.start", "forced", 1, ["arm:unfold.success.unfolded"]),
        ("dock_station.start", "forced", 1, ["arm:unfold.success.unfolded"]),
    ]


def test_help_explains(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for command in ("demo", "parse", "net", "unsafe", "explore", "ctl"):
        assert command in out


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sub


def test_lazy_commands_list_their_modules_own_help() -> None:
    full = build_parser()
    assert build_parser("").format_help() == full.format_help()  # skinet --help without importing them
    assert build_parser("unsafe").format_help() == full.format_help()
    names = [name for _, _, helps in LAZY_COMMANDS for name in helps]
    assert names == ["demo", "record", "rosbag", "timeline", "replay", "conform", "run", "router", "fleet", "plan", "goal", "dashboard",
                     "watch", "check", "foxglove", "client-config"]
    for name in names:
        lazy = build_parser(name)
        assert lazy.format_help() == full.format_help()
        assert _subparsers(lazy).choices[name].format_help() == _subparsers(full).choices[name].format_help()


def test_lazy_command_runs_its_module(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["record", "--help"])
    assert info.value.code == 0
    assert "-o LOG.jsonl|LOG.mcap, --output LOG.jsonl|LOG.mcap" in capsys.readouterr().out
    with pytest.raises(SystemExit) as info:
        main(["record"])
    out, err = capsys.readouterr()
    assert info.value.code == 2 and out == ""
    assert err.splitlines()[-1] == ("skinet record: error: the following arguments are required: SYSTEM_NAME "
                                    "(see skinet record --help)")
    with pytest.raises(SystemExit) as info:
        main(["record", "spot_arm"])
    out, err = capsys.readouterr()
    assert err.splitlines()[-1] == ("skinet record: error: one of the arguments -o/--output --bundle is required "
                                    "(see skinet record --help)")


def test_unsafe_imports_no_service_module() -> None:
    """Start-up (issue 10 (d)): no Zenoh, pydantic, web server, plotting, ROS type library (issue 33), chain or
    service for `skinet unsafe` (only the options the services share, SIGUSR1's stacks and the chains' text helpers)."""
    code = ("import sys; from skinet_cli.main import main; code = main(['unsafe', sys.argv[1]]); "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'zenoh', 'pydantic', 'aiohttp', 'matplotlib', "
            "'scipy', 'rosbags'} | {m for m in sys.modules if m.startswith(('services.', 'chains.')) and m not in "
            "('services.common', 'services.common.options', 'services.common.environment', "
            "'services.common.memory', 'services.common.stacks', 'chains.render', 'chains.pilot_lines')})); "
            "raise SystemExit(code)")
    done = subprocess.run([sys.executable, "-c", code, SYSTEM], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "[]"
    assert done.stdout.splitlines()[-2].startswith("prediction: complete, 63 markings in ")


# -- issue 27, item 8: the small ones a new user hit -------------------------------------------

TELEOP = {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"},
                   "running": ["teleop"]}}


def test_state_takes_inline_json_or_a_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    _, from_file, _ = run(capsys, "unsafe", SYSTEM, "--state", state(tmp_path, TELEOP), "--no-predict", "--json")
    code, inline, err = run(capsys, "unsafe", SYSTEM, "--state", json.dumps(TELEOP), "--no-predict", "--json")
    assert (code, err) == (0, "")
    assert json.loads(inline) == json.loads(from_file)
    assert [u["transition"] for u in json.loads(inline)["unsafe"]] == ["arm_ready.start"]
    code, _, err = run(capsys, "unsafe", SYSTEM, "--state", ' {"spot": {"running": ["teleop"]}}')
    assert code == 1 and err.startswith("<state>: error: impossible state: 'spot' is not stable: invariant violated")


def test_demo_help_says_how_many_runs_it_plays(capsys: pytest.CaptureFixture[str]) -> None:
    from skinet_cli.demo import MISSIONS

    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert f"Play {len(MISSIONS)} runs through the whole chain" in help_text
    assert "skillsets/missions/{unassisted,assisted,pilot,mobile_unassisted,mobile_assisted}.toml" in help_text.replace(
        " ", "")
    code, out, _ = run(capsys, "demo", "--core", "--no-predict")
    runs = [line for line in out.splitlines() if line.startswith("== ")]
    assert code == 0 and len(runs) == len(MISSIONS) + 1 == 6 and runs[-1] == "== the runs side by side"


def test_live_demo_options_are_checked_before_anything_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """``skinet demo --live`` plays one run of the whole chain; its options mean nothing without it."""
    missions = "skillsets/missions/"
    for argv, error in [
        (["--dashboard", "8080"], "--dashboard needs --live"),
        (["--speed", "10"], "--speed needs --live"),
        (["--connect", "tcp/127.0.0.1:7447"], "--connect needs --live"),
        (["--live", "--core"], "--live plays the whole chain, not --core"),
        (["--live", missions + "unassisted.toml", missions + "assisted.toml"],
         "--live plays one run at a time (got 2 scenarios)"),
    ]:
        assert run(capsys, "demo", *argv) == (1, "", f"skinet: error: {error}\n"), argv
    with pytest.raises(SystemExit):
        main(["demo", "--live", "--speed", "-1"])
    assert capsys.readouterr().err == ("skinet demo: error: argument --speed: expected a number >= 0, got '-1' "
                                       "(see skinet demo --help)\n")


def test_max_depth_zero_says_no_layer_was_expanded(capsys: pytest.CaptureFixture[str]) -> None:
    _, out, _ = run(capsys, "explore", SYSTEM, "--max-depth", "0")
    assert "  depth      none (no layer expanded)" in out.splitlines()
    _, out, _ = run(capsys, "unsafe", SYSTEM, "--max-depth", "0")
    assert out.splitlines()[-1].startswith("prediction: TRUNCATED by depth (only the live marking stored, no layer "
                                           "expanded; unknown constraints possible), 1 marking in ")
    _, out, _ = run(capsys, "ctl", SYSTEM, "EF spot:Busy", "--max-depth", "0")
    assert out.splitlines()[-1] == ("truncated by depth (only the live marking stored, no layer expanded): "
                                    "answers are three-valued")
    assert "-1" not in out


def test_explore_progress_shows_progress_or_says_why_not(capsys: pytest.CaptureFixture[str],
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    import skinet_cli.main as cli

    code, _, err = run(capsys, "explore", SYSTEM, "--progress")
    assert code == 0
    assert re.fullmatch(r"progress: none to show, the exploration took [\d.]+ ms \(a report comes every 0.2 s\)\n",
                        err)
    monkeypatch.setattr(cli, "PROGRESS_EVERY", 0.0)  # as if every chunk took 0.2 s: a report per chunk
    code, _, err = run(capsys, "explore", SYSTEM, "--progress")
    assert code == 0 and err.splitlines() and all(re.fullmatch(r"  layer \d+: \d+ markings?, [\d.]+ m?s", line)
                                                  for line in err.splitlines())
    assert err.splitlines()[-1].startswith("  layer 9: 63 markings, ")


def test_hints_name_the_skinet_that_was_called(tmp_path: Path) -> None:
    """A ``skinet`` that PATH does not find (a clone's ``.venv/bin/skinet``) prints hints that call it by the
    path it was started with; one that PATH finds prints plain ``skinet`` (skinet/files/program.py)."""
    script = Path(sys.executable).parent / "skinet"
    typed = os.path.relpath(script, tmp_path)
    hint = "for a system try {0} net {1} or {0} unsafe {1}\n"
    for path, name in ((os.defpath, typed), (f"{script.parent}{os.pathsep}{os.defpath}", "skinet")):
        done = subprocess.run([typed, "parse", SYSTEM], cwd=tmp_path, capture_output=True, text=True, timeout=60,
                              env={**os.environ, "PATH": path})
        assert done.returncode == 1 and done.stderr.endswith(hint.format(name, SYSTEM)), done.stderr


def test_python_hint_is_the_interpreter_beside_the_script(monkeypatch: pytest.MonkeyPatch) -> None:
    from skinet.files import program

    script = Path(sys.executable).parent / "skinet"
    monkeypatch.setenv("PATH", os.defpath)
    for argv0, expected in ((str(script), (str(script), str(script.with_name("python")))),
                            ("/no/such/place/skinet", ("/no/such/place/skinet", sys.executable)),
                            (str(ROOT / "skinet_cli" / "main.py"), ("skinet", "python"))):
        monkeypatch.setattr(sys, "argv", [argv0])
        program.skinet.cache_clear()
        try:
            assert (program.skinet(), program.python()) == expected
        finally:
            program.skinet.cache_clear()


@pytest.mark.parametrize("what", ["skinet router", "python -m services.monitor"])
def test_sigusr1_prints_every_threads_stack_and_the_command_goes_on(what: str) -> None:
    """What to send a hung command or service before killing it (docs/operator.md)."""
    import signal

    from tests.loopback import free_port
    from tests.processes import start_module, start_skinet, stop

    listen = f"tcp/127.0.0.1:{free_port()}"
    if what == "skinet router":
        proc, ready = start_skinet("router", "--listen", listen, "--no-auth"), "listening"
    else:
        proc = start_module("services.monitor", "skillsets/spot_arm.toml", "--mode", "peer", "--listen", listen,
                            "--no-multicast-scouting")
        ready = "monitoring spot_arm"
    try:
        assert proc.stdout is not None
        while ready not in (line := proc.stdout.readline()):
            assert line, f"{what} ended before '{ready}'"
        proc.send_signal(signal.SIGUSR1)
        lines = []
        while not any(line.startswith("Current thread 0x") for line in lines):
            lines.append(proc.stdout.readline())
            assert lines[-1], f"the output ended: {lines}"
        assert lines[-1].endswith("(most recent call first):\n")
        assert proc.stdout.readline().startswith('  File "'), lines  # its frames follow
        assert proc.poll() is None
    finally:
        assert stop(proc) in (0, -signal.SIGTERM)
