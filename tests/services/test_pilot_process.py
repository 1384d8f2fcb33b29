"""The pilot as a process (issue 24): ``python -m services.pilot`` (a one-line error on a bad system file, a
liveliness token and a status on ``get`` with no monitor running, a clean stop on SIGTERM), and the pilot
that ``skinet run`` embeds, driving the robot that connects to it."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

from services.bridge_ros2 import start_bridge
from services.simulator import Simulator
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import PilotStatus
from tests.services.conftest import REPO, free_port, open_client, start_skinet
from tests.services.pilot_robot import Implementations, Statuses, ask_goal, goal


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
        impl = Implementations(sim, system)
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
