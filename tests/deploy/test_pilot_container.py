"""The ``pilot`` service of ``compose.yaml`` (onboard profile; issue 24 items 1 and 2): its own
container on the robot's network with the ``pilot`` login alone, beside the monitor, the bridge
and a predictor; a goal from the ``operator`` login through the router is accepted and driven on
the robot, an observer's is refused (docs/semantics.md §7, §8).

The robot is the simulator's managers on the host, logged in to the stack's router as ``robot``
with that user's files, as the robot's ROS 2 gateway logs in from outside the compose network
(docs/robot.md); the test ends the skill the pilot started as the robot's implementation would.
The operator's files come out of the vault through the job ``secrets``, as docs/deployment.md
shows.  The image is test_containers' (``$SKINET_TEST_IMAGE``, default ``skinet-live:local``).
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from deploy_support import REPO, SYSTEM, Tokens, free_port, wait_until
from services.simulator.service import Simulator
from skinet.system.load import load_system, load_typemap
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import PilotGoalReply, PilotGoalRequest, PilotStatus
from tests.services.pilot_robot import Statuses
from test_containers import SECRETS_IN_IMAGE, Stack, host_login, image  # noqa: F401 (the image fixture)

pytestmark = pytest.mark.slow

SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
OPERATOR_FILES = "operator.password tls/ca.pem tls/operator.pem tls/operator.key"


@pytest.fixture(scope="module")
def onboard(image: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Stack, str]]:
    """Router, bridge, monitor and pilot of the onboard profile, and one predictor (offboard: the pilot
    acts only on fresh predictions); yields the stack and the router's host endpoint."""
    port = free_port()
    env = {**os.environ, "COMPOSE_PROFILES": "onboard,offboard,demo", "SKINET_IMAGE": image,
           "SKINET_ROUTER_PORT": f"127.0.0.1:{port}", "SKINET_PREDICTORS": "1", "SKINET_LOG_LEVEL": "INFO"}
    s = Stack(f"skinet-pilot-{os.getpid()}", env)
    try:
        s.compose("up", "-d", "--no-build", "router", "bridge", "monitor", "predictor", "pilot", timeout=240)
        yield s, f"tls/127.0.0.1:{port}"
    finally:
        (tmp_path_factory.mktemp("compose") / "compose.log").write_text(s.logs())
        s.down()


def operator_config(stack: Stack, folder: Path, endpoint: str) -> Path:
    """docs/deployment.md ("Operators"): the operator's files out of the vault through the job
    ``secrets`` (no running service holds them), then ``skinet client-config --user operator``."""
    target = folder / "operator"
    target.mkdir(parents=True, exist_ok=True)
    compose = " ".join(shlex.quote(a) for a in stack.command)
    r = subprocess.run(f"{compose} run --rm -T secrets tar -C {SECRETS_IN_IMAGE} -c {OPERATOR_FILES} "
                       f"| tar -x --no-same-owner -C {shlex.quote(str(target))}", shell=True, cwd=REPO,
                       env=stack.env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and sorted(str(p.relative_to(target)) for p in target.rglob("*") if p.is_file()) == [
        "operator.password", "tls/ca.pem", "tls/operator.key", "tls/operator.pem"], r
    output = folder / "operator.json5"
    r = subprocess.run([sys.executable, "-m", "skinet_cli.main", "client-config", "--secrets", str(target),
                        "--user", "operator", "--connect", endpoint, "-o", str(output)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r
    return output


def ask(session: zenoh.Session, client: str, request: PilotGoalRequest) -> list[PilotGoalReply]:
    return [decode(r.ok.payload.to_bytes(), PilotGoalReply)
            for r in session.get(keys.pilot_goal(SYSTEM, client), payload=encode(request), timeout=10.0)
            if r.ok is not None]


def test_the_pilot_container_drives_an_operators_goal(onboard: tuple[Stack, str],
                                                      tmp_path_factory: pytest.TempPathFactory) -> None:
    stack, endpoint = onboard
    folder = tmp_path_factory.mktemp("secrets")
    for user in ("observer", "robot"):
        stack.client_config(user, folder, endpoint)
    operator_config(stack, folder, endpoint)
    observer, robot_session, operator = (host_login(onboard, folder, u) for u in ("observer", "robot", "operator"))
    system, _ = load_system(SYSTEM_FILE)
    robot = Simulator(robot_session, system, load_typemap(SYSTEM_FILE))
    tokens, statuses = Tokens(observer), Statuses(observer)
    try:
        wait_until(lambda: all(tokens.of(s) for s in ("pilot", "monitor", "bridge_ros2", "predictor")), 120,
                   f"the services' liveliness tokens (got {sorted(tokens.alive)})")
        (pilot_container,) = stack.containers("pilot")
        (instance,) = tokens.of("pilot")
        # It answers its status to anybody who reads (the observer here).
        replies = [decode(r.ok.payload.to_bytes(), PilotStatus)
                   for r in observer.get(keys.pilot_status(SYSTEM), timeout=5.0) if r.ok is not None]
        assert [(s.system, s.pilot, s.goal_id) for s in replies] == [(SYSTEM, instance, 0)]
        hostname = subprocess.run(["docker", "inspect", "-f", "{{.Config.Hostname}}", pilot_container],
                                  capture_output=True, text=True, check=True).stdout.strip()
        assert instance.rsplit("-", 1)[0] == hostname  # <hostname>-<pid>: the token is the pilot container's

        goal = PilotGoalRequest(system=SYSTEM, goals=["run spot:init_power"], mode="drive")
        # The observer may read, not set goals: the router drops its query, on its own key or the operator's.
        assert ask(observer, "observer", goal) == [] and ask(observer, "operator", goal) == []
        assert robot.skill_status("spot", "init_power") == (False, "")

        (reply,) = ask(operator, "operator", goal)
        assert (reply.accepted, reply.reason, reply.answer) == (True, "", "cyclic"), reply
        statuses.state("waiting for outcome", reply.goal_id, timeout=60)
        # The pilot says it waits for the outcome as it sends: its request reaches the robot a moment later.
        wait_until(lambda: robot.skill_status("spot", "init_power")[0], 30, "the pilot's request on the robot")
        assert robot.skill_status("spot", "init_power") == (True, f"pilot-{instance}-1")  # the pilot's execution
        assert robot.terminate("spot", "init_power", "success", "powered_on")
        last = statuses.state("reached", reply.goal_id, timeout=30)
        assert (last.client, last.mode, last.commands, last.denied, last.retries) == ("operator", "drive", 1, 0, {})
        states = statuses.states(reply.goal_id)
        assert states.index("waiting for outcome") < states.index("reached") == len(states) - 1, states
    finally:
        tokens.close()
        robot.close()
        for s in (observer, robot_session, operator):
            s.close()
