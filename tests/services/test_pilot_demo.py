"""The demo's third run (issue 24, item 5): the paper's mission from a goals file, driven by the pilot.

Simulated managers whose skills end by themselves (two failures injected: the arm blocked
once on its way to ready, one not_arrived) -> CDR -> bridge -> monitor -> predictor -> pilot
-> the monitor's strict check -> the pilot's requests, on one embedded Zenoh session, and
over rmw_zenoh keys behind a router.  The chain's moves must be the core flight's, move for
move (:func:`skinet.pilot.flight.fly`); the pilot reaches every goal with no violation and no
command denied; ``skinet demo`` prints the run beside the paper's two as a table.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from chains.pilot_chain import PilotRecord, run_pilot_chain
from services.simulator import Simulator
from skinet.system.load import load_goals, load_system, load_typemap
from skinet.files.read import read_text
from skinet.pilot.flight import fly
from skinet.pilot.run import Outcomes, parse_pilot_run
from skinet.ros.keys import KeyStyle, parse_rmw_attachment
from skinet_cli.main import main

MISSIONS = Path(__file__).resolve().parents[2] / "skillsets" / "missions"
PILOT = MISSIONS / "pilot.toml"
# The favourable protocol is 30 commands (init_power, stand_up, 7 per trap); the blocked arm costs
# arm_moving_to_RD, arm_RD_to_HP and arm_ready again, the not_arrived walk one more go_to_waypoint.
COMMANDS, MOVES = 30 + 3 + 1, 2 * (30 + 3 + 1)


@pytest.fixture(scope="module")
def paper() -> tuple:
    run = parse_pilot_run(read_text(PILOT), str(PILOT))
    system, _ = load_system(MISSIONS / run.system)
    typemap = load_typemap(MISSIONS / run.system)
    goals = load_goals(MISSIONS / run.goals, system, typemap)
    return run, system, typemap, goals


def check_flight(record: PilotRecord, paper: tuple) -> None:
    run, system, _, goals = paper
    flight = fly(system, goals, Outcomes.of(run, system))
    assert (flight.end, flight.goals, len(flight.moves)) == ("reached", 29, MOVES)
    assert [(e.skillset, e.transition) for e in record.events] == flight.moves
    assert (record.status.state, record.status.reason, record.status.index) == ("reached", "", 28)
    assert (record.commands, record.status.commands, record.status.denied) == (COMMANDS, COMMANDS, 0)
    assert record.violations == [] and record.retries == 2
    failed = [(e.skillset, e.skill, e.mode) for e in record.ends if e.kind == "failure"]
    assert failed == [("manipulator", "arm_ready", "blocked"), ("spot", "go_to_waypoint", "not_arrived")]
    assert all(e.ok for e in record.ends) and len(record.ends) == COMMANDS
    # After the blocked arm, the pilot planned again: to RD, home, and arm_ready once more.
    at = record.events.index(next(e for e in record.events if e.transition == "arm_ready.failure.blocked"))
    assert [e.transition for e in record.events[at + 1:at + 7:2]] == [
        "arm_moving_to_RD.start", "arm_RD_to_HP.start", "arm_ready.start"]
    assert "driving" in record.states and "waiting for outcome" in record.states


def test_the_pilot_drives_the_papers_mission_through_the_chain(paper) -> None:
    run, system, typemap, _ = paper
    record = run_pilot_chain(system, typemap, run, read_text(MISSIONS / run.goals), duration=0.05)
    assert record.reply.accepted and (record.reply.answer, record.reply.moves) == ("cyclic", 4)  # stand up
    check_flight(record, paper)


def test_the_pilot_drives_managers_on_rmw_zenoh_keys_behind_a_router(paper, client_factory) -> None:
    """Item 5's ROS 2 chain on rmw_zenoh: the pilot's requests are CDR on the managers' rmw_zenoh keys, with
    the 33-byte attachments of one writer; the managers decode them, their skills run, the bridge reports."""
    run, system, typemap, _ = paper
    style = KeyStyle(rmw_zenoh=True, domain=3)
    session = client_factory()
    requests: list[tuple[str, bytes | None]] = []
    spy = client_factory().declare_subscriber(
        "3/**/skill/*/request/**", lambda s: requests.append((str(s.key_expr), s.attachment and s.attachment.to_bytes())))
    simulator = Simulator(client_factory(), system, typemap, style=style)
    try:
        record = run_pilot_chain(system, typemap, run, read_text(MISSIONS / run.goals), duration=0.05,
                                 session=session, simulator=simulator, style=style)
    finally:
        simulator.close()
        spy.undeclare()
    check_flight(record, paper)
    starts = [k for k, _ in requests]
    assert len(starts) == COMMANDS and all(k.startswith(("3/spot/spot_skillset_manager/spot_skillset/skill/",
                                                          "3/kinova/manipulator_skillset_manager/")) for k in starts)
    assert "skill/go_to_waypoint/request/spot_skillset_interfaces::msg::dds_::SkillGoToWaypointRequest_/RIHS01_" \
        in next(k for k in starts if "go_to_waypoint" in k)
    writers = {parse_rmw_attachment(a)[2] for _, a in requests if a is not None}
    sequences = [parse_rmw_attachment(a)[0] for _, a in requests if a is not None]
    assert len(writers) == 1 and len(sequences) == COMMANDS and sequences == sorted(set(sequences))


def test_demo_prints_the_pilot_run_beside_the_papers(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["demo", str(MISSIONS / "unassisted.toml"), str(MISSIONS / "assisted.toml"), str(PILOT)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert (f"== pilot run ({PILOT}): 29 goals ({MISSIONS.parent / 'goals' / 'paper_mission.toml'}), drive mode, "
            "system spot_arm\n"
            "   failures injected: run 1 of manipulator:arm_ready ends blocked, run 2 of spot:go_to_waypoint ends "
            "not_arrived\n") in out
    assert "  step  10  t=" in out and "manipulator:arm_ready.failure.blocked " in out
    assert "  step  26  t=" in out and "spot:go_to_waypoint.failure.not_arrived " in out
    assert ("   pilot: reached; 29 goals, 68 moves, 34 commands sent, 0 denied by the check, 2 retries\n"
            "   violations: 0\n") in out
    assert out.endswith("== the runs side by side\n"
                        "   run         commands  moves  retries  violations  denied\n"
                        "   unassisted        31     62        0           3       -\n"
                        "   assisted          30     60        0           0       -\n"
                        "   pilot             34     68        2           0       0\n")
    assert "rate limit" not in err


def test_demo_core_flies_the_pilot_run(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--core", "--no-predict", str(PILOT)]) == 0
    out = capsys.readouterr().out
    assert "   chain: core only (the pilot's drive mode on the live nets; no simulator, Zenoh, check)\n" in out
    assert "   pilot: reached; 29 goals, 68 moves, 34 commands sent, 2 retries\n" in out
    assert out.endswith("   pilot        34     68        2           0       -\n")


def test_a_pilot_run_that_fails_is_an_unexpected_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Three failures of one skill in one goal end the mission failed: exit status 3, the reason said."""
    run = tmp_path / "stubborn.toml"
    failures = "".join(f'\n[[failures]]\nskill = "spot:init_power"\nrun = {n}\nmode = "no_battery"\n' for n in (1, 2, 3))
    run.write_text(f'[pilot]\nname = "stubborn"\nsystem = "{MISSIONS.parent / "spot_arm.toml"}"\n'
                   f'goals = "{MISSIONS.parent / "goals" / "paper_mission.toml"}"\n{failures}')
    assert main(["demo", "--core", "--no-predict", str(run)]) == 3
    out, err = capsys.readouterr()
    assert "   pilot: failed: spot:init_power failed 3 times (last: no_battery); 29 goals, 6 moves, 3 commands sent, " \
           "3 retries\n" in out
    assert f"skinet demo: {run}: the pilot's mission ended failed: spot:init_power failed 3 times (last: no_battery)" \
        in err


def test_a_pilot_run_that_does_not_end_is_said_not_crashed(monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """The chain not letting the mission end (a pilot paused for good) is an unexpected end, with the reason."""
    import chains.pilot_chain
    from chains.chain import ChainError

    def stuck(*_args: object, **_options: object) -> None:
        raise ChainError("the pilot's mission did not end within 120 s: it is paused (spot is lost) at goal 3 of 29")

    monkeypatch.setattr(chains.pilot_chain, "run_pilot_chain", stuck)
    assert main(["demo", "--no-predict", str(PILOT)]) == 3
    out, err = capsys.readouterr()
    assert "   pilot: the run did not end: the pilot's mission did not end within 120 s: it is paused (spot is lost) " \
           "at goal 3 of 29\n" in out
    assert out.endswith("== the runs side by side\n   run  commands  moves  retries  violations  denied\n")
    assert err == (f"skinet demo: {PILOT}: the pilot run did not end: the pilot's mission did not end within 120 s: "
                   "it is paused (spot is lost) at goal 3 of 29\n")


def test_bad_pilot_runs_are_refused_before_anything_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A pilot run's errors name the file, line and column (its goals file's too)."""
    bad = tmp_path / "bad.toml"
    bad.write_text(f'[pilot]\nname = "bad"\nsystem = "{MISSIONS.parent / "spot_arm.toml"}"\ngoals = "goals.toml"\n'
                   '\n[[failures]]\nskill = "manipulator:arm_ready"\nmode = "ready"\n')
    (tmp_path / "goals.toml").write_text('[[goals]]\nrun = "spot:fly"\n')
    assert main(["demo", str(MISSIONS / "assisted.toml"), str(bad)]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err == (f"{bad}:8:1: error: failure 1: 'ready' is not a failure mode of "
                                 "manipulator:arm_ready (failure modes: blocked)\n")
    bad.write_text(bad.read_text().replace('mode = "ready"', 'mode = "blocked"'))
    assert main(["demo", str(bad)]) == 1
    err = capsys.readouterr().err
    assert err == (f"{tmp_path / 'goals.toml'}:2:13: error: unknown skill 'fly' of 'spot' (expected one of: "
                   "init_power, safe_poweroff, stand_up, sit_down, go_to_waypoint, teleop)\n")


def test_a_pilot_run_plays_live_with_each_change_of_the_pilots_status() -> None:
    """``skinet demo --live`` on a pilot run: the chain listens for the views, the pilot's status is printed as it
    changes (the lines ``skinet goal`` prints), then the run as without --live, and the chain lingers."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "skinet_cli.main", "demo", "--live", str(PILOT), "--speed", "0",
                           "--linger", "0", "--no-multicast-scouting"], cwd=MISSIONS.parents[1], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert lines[:4] == [
        "== live at speed 0: the pilot drives the run below, its status as it changes",
        f"== pilot run ({PILOT}): 29 goals ({MISSIONS.parent / 'goals' / 'paper_mission.toml'}), drive mode, "
        "system spot_arm",
        "   failures injected: run 1 of manipulator:arm_ready ends blocked, run 2 of spot:go_to_waypoint ends "
        "not_arrived",
        "   pilot: driving \u2014 goal 1/29 reach spot:Standing, next spot:init_power.start, 4 moves left, "
        "0 commands sent"]
    statuses = [line for line in lines if line.startswith("   pilot: ") and "\u2014" in line]
    assert statuses[-1] == "   pilot: reached \u2014 goal 29/29 run spot:teleop, 34 commands sent"
    assert sum("waiting for outcome: the effect of" in line for line in statuses) == COMMANDS
    assert f"   pilot: reached; 29 goals, {MOVES} moves, {COMMANDS} commands sent, 0 denied by the check, 2 retries" \
        in lines and "   violations: 0" in lines
    assert "  skinet watch spot_arm -e tcp/127.0.0.1:" in done.stderr
    assert done.stderr.endswith("skinet demo: the run is over; the chain keeps running for the views for 0 s\n")


def test_a_live_pilot_run_keeps_its_pilot_while_the_chain_lingers() -> None:
    """Issue 32: the chain "keeps running for the views" after a live pilot run, and its pilot with it: a goal
    asked then is answered by that pilot (here a pause, with no goal left to pause)."""
    import re
    import subprocess
    import sys

    demo = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "demo", "--live", str(PILOT), "--speed", "0",
                             "--linger", "300", "--no-multicast-scouting"], cwd=MISSIONS.parents[1],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        endpoint, lines = None, []
        for line in demo.stderr:
            lines.append(line)
            found = re.search(r" -e (tcp/127\.0\.0\.1:\d+)", line)
            endpoint = endpoint or (found and found.group(1))
            if line.startswith("skinet demo: the run is over"):
                break
        assert endpoint and lines[-1] == ("skinet demo: the run is over; the chain keeps running for the views for "
                                          "300 s\n"), "".join(lines)
        asked = subprocess.run([sys.executable, "-m", "skinet_cli.main", "goal", "spot_arm", "--pause", "-e", endpoint],
                               capture_output=True, text=True, timeout=120)
        assert (asked.returncode, asked.stderr) == (
            2, "pause rejected by the pilot: no goal is being followed: nothing to pause\n"), asked.stdout
    finally:
        demo.terminate()
        demo.wait(30)
