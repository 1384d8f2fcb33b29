"""The pilot as a process (issue 24): ``python -m services.pilot`` (a one-line error on a bad system file, a
liveliness token and a status on ``get`` with no monitor running, a clean stop on SIGTERM), and the pilot
that ``skinet run`` embeds, driving the robot that connects to it, or the simulated robot of ``skinet run
--simulate`` with ``skinet goal --drive`` from another process."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path
from subprocess import CompletedProcess

from services.bridge_ros2 import start_bridge
from services.simulator import Simulator
from services.simulator.world import World
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import PilotStatus
from tests.processes import Watched
from tests.services.conftest import REPO, free_port, open_client, start_skinet
from tests.services.pilot_robot import Statuses, ask_goal, goal


def test_a_bad_system_file_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[system]\nname = "x y"\n')
    out = subprocess.run([sys.executable, "-m", "services.pilot", str(bad)], cwd=REPO, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 1
    assert out.stderr.count("\n") == 1 and out.stderr.startswith(f"{bad}:"), out.stderr


def test_the_pilot_process_waits_for_a_monitor_and_stops_cleanly(spawn, zenoh_args, client, watch) -> None:
    tokens = watch(client, keys.alive("spot_arm", "pilot", "*"))
    proc = spawn("services.pilot", str(REPO / "skillsets" / "spot_arm.toml"), "--instance", "cli",
                 "--response-timeout", "2", *zenoh_args)
    tokens.wait_for(keys.alive("spot_arm", "pilot", "cli"), timeout=30)
    [reply] = list(client.get(keys.pilot_status("spot_arm"), timeout=5.0))
    status = decode(reply.ok.payload.to_bytes(), PilotStatus)
    assert (status.pilot, status.state, status.reason) == (
        "cli", "waiting for monitor", "no monitor of spot_arm is running (no token on skinet/spot_arm/alive/monitor/*)")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=10) == 0
    tokens.wait_gone(keys.alive("spot_arm", "pilot", "cli"))


def test_skinet_run_drives_a_goal_with_its_embedded_pilot(spot_arm) -> None:
    """The robot (simulated managers and the bridge) connects to ``skinet run``, whose pilot drives a goal."""
    system, typemap = spot_arm
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = start_skinet("run", str(REPO / "skillsets" / "spot_arm.toml"), "--listen", endpoint,
                        "--no-multicast-scouting", "--duration", "60")
    session = None
    try:
        assert proc.stdout is not None
        banner = [proc.stdout.readline() for _ in range(6)]
        assert banner[-1] == ("  pilot: goals on skinet/spot_arm/pilot/goal/<client> (<client>: your login, 'local' "
                              "without one), status on skinet/spot_arm/pilot/status\n"), banner
        session = open_client(endpoint)
        sim = Simulator(session, system, typemap)
        bridge = start_bridge(session, system, typemap)
        impl = World(sim)
        statuses = Statuses(session)
        try:
            reply = ask_goal(session, goal("reach spot:Standing", mode="drive"), client=keys.LOCAL_CLIENT)
            assert (reply.accepted, reply.answer) == (True, "cyclic"), reply
            done = statuses.state("reached", reply.goal_id)
            assert (done.commands, done.denied, impl.ended) == (
                2, 0, ["spot:init_power.success.powered_on", "spot:stand_up.success.standing"])
        finally:
            impl.close()
            bridge.close()
            sim.close()
    finally:
        if session is not None:
            session.close()
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)


WAYPOINT = "go_to_waypoint.target = {x = 12.0, y = 3.5, z = 0.0}"


def simulate_and_drive(run_args: list[str], system: str, goal_args: list[str]) -> tuple[list[str], CompletedProcess]:
    """``skinet run ... --simulate`` as a process, then, once it printed how to reach it, ``skinet goal ...
    --drive -e ENDPOINT`` as another (the endpoint read from the goal line it printed): the run's first lines and
    the goal's process."""
    run = Watched([sys.executable, "-m", "skinet_cli.main", "run", *run_args, "--simulate"], REPO)
    try:
        run.wait_for(lambda text: f"  skinet goal {system} " in text, "the goal line", timeout=120)
        line = next(x for x in run.lines if x.startswith(f"  skinet goal {system} "))
        endpoint = line.split(" -e ")[1].split()[0]
        done = subprocess.run([sys.executable, "-m", "skinet_cli.main", "goal", system, *goal_args, "--drive",
                               "-e", endpoint], cwd=REPO, capture_output=True, text=True, timeout=120)
    finally:
        stopped = run.stop()
    assert stopped == 0, run.text  # SIGTERM ends it cleanly
    return run.lines, done


def test_skinet_run_simulate_is_a_robot_that_skinet_goal_drives_to_the_goal() -> None:
    """Try the pilot in one command (docs/pilot.md): the paper's robot simulated by ``skinet run --simulate``
    (its managers and bridge on the run's session, each skill ending by itself a second after it starts), and
    ``skinet goal`` in another process driving it to a waypoint: power on, stand up, walk."""
    lines, done = simulate_and_drive(["skillsets/spot_arm.toml"], "spot_arm",
                                     ["run spot:go_to_waypoint", "--inputs", WAYPOINT])
    assert ("  the robot: simulated here, with its bridge; each skill ends by itself 1 s after it starts (failure "
            "rate 0, seed 0)") in lines, lines
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines()[-1] == "reached \u2014 3 commands sent", done.stdout
    assert [x.split(". ", 1)[1] for x in done.stdout.splitlines() if x.startswith("  ") and ". spot:" in x] == [
        "spot:init_power.start", "spot:stand_up.start",
        "spot:go_to_waypoint.start with {target = {x = 12.0, y = 3.5, z = 0.0}}"]


def test_skinet_run_simulate_docks_the_nav2_robot_through_its_binding() -> None:
    """The Nav2 example has no skillset manager: ``--simulate`` serves its bound action servers, lifecycle node
    and topics (a first /battery_state that shows battery Ok and Charging), the bound bridge reads them, and
    the pilot undocks then docks the robot with the goal's dock id, through the action servers."""
    lines, done = simulate_and_drive(["examples/nav2/nav2.toml", "--skill-duration", "0.2"], "nav2",
                                     ["run nav2:dock_robot", "--inputs", 'dock_robot.dock = "home_dock"'])
    assert ("  the robot: simulated here, with its bridge; each skill ends by itself 0.2 s after it starts (failure "
            "rate 0, seed 0)") in lines, lines
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines()[-1] == "reached \u2014 2 commands sent", done.stdout


def test_skinet_runs_memory_limit_is_its_pilots() -> None:
    """The pilot that ``skinet run`` embeds plans within the run's ``--memory-limit`` (the run's whole process):
    past it the goal is refused with why, never followed.  Before, it kept its own 1 GiB."""
    _, done = simulate_and_drive(["skillsets/spot_arm.toml", "--memory-limit", "1MiB"], "spot_arm",
                                 ["reach spot:Standing"])
    assert (done.returncode, done.stdout) == (2, ""), done.stdout + done.stderr
    assert done.stderr == ("goal rejected by the pilot: goal 'reach spot:Standing' has no plan from the live state: "
                           "unknown: the memory limit (1 MiB, the whole process) was reached before the fixpoints "
                           "ended (0 markings, exploration cut by the memory)\n")
