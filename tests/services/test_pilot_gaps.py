"""The pilot across gaps (docs/pilot.md, *Missed outcomes*; issue 30): a skill it started that ended
while it could not see it is never started again silently.  The paper's robot through a real router
(:class:`~tests.services.pilot_robot.Robot`); the monitor is restarted on its own session."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable

import pytest
import zenoh

from services.simulator.world import World
from skinet.ros.interfaces import status_request_topic
from skinet.wire.messages import MissedOutcome, PilotGoalRequest
from tests.services.conftest import REPO, client_args
from tests.services.pilot_robot import WALK, Gui, Robot, ask_goal, goal
from tests.services.test_monitor import wait_until


def restart_monitor_while(robot: Robot, impl: World, skill: str) -> None:
    """Stop the monitor, let ``skill`` (held) end on the robot meanwhile, start a fresh monitor."""
    robot.monitor.close()
    robot.monitor = None
    robot.statuses.first(lambda s: s.state == "waiting for monitor", what="waiting for the monitor")
    impl.release("spot", skill)
    deadline = time.monotonic() + 30.0
    while robot.sim.skill_status("spot", skill)[0]:
        assert time.monotonic() < deadline, f"{skill} did not end"
        time.sleep(0.01)
    robot.start_monitor()


def test_a_skill_that_ended_during_a_monitor_restart_is_not_started_again_but_asked_about(robot: Robot,
                                                                                          router: str) -> None:
    """teleop's success and failure leave the same resources: the pilot cannot tell, pauses, and goes on
    after the operator's answer (before: teleop was started twice, 'reached — 2 commands sent')."""
    impl = World(robot.sim, holding=[("spot", "teleop")])
    try:
        reply = ask_goal(robot.observer, goal("run spot:teleop", mode="drive"))
        robot.statuses.first(lambda s: s.reason == "the outcome of spot:teleop", what="teleop running")
        restart_monitor_while(robot, impl, "teleop")
        paused = robot.statuses.first(lambda s: s.unknown is not None, what="an unknown outcome")
        assert paused.unknown == MissedOutcome(skillset="spot", skill="teleop", gap="while the monitor was restarted",
                                               candidates=["teleop.success.done", "teleop.failure.link_lost"])
        assert (paused.state, paused.reason) == ("paused", (
            "outcome unknown: spot:teleop ended while the monitor was restarted; success.done or failure.link_lost "
            "would explain the resources: confirm success, failure or rerun (the pilot does not start it again on "
            "its own)"))
        assert paused.notes == ["spot:teleop ended while the monitor was restarted: outcome unknown"]
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:teleop.start"]
        bad = ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="confirm"))
        assert (bad.accepted, bad.reason) == (False, "confirm needs an answer: success, failure or rerun")
        answered = subprocess.run([sys.executable, "-m", "skinet_cli.main", "goal", "spot_arm", "--confirm", "success",
                                   *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)
        assert (answered.returncode, answered.stdout.splitlines()[0]) == (0, "confirm success: done (goal 1)"), \
            answered.stdout + answered.stderr
        done = robot.statuses.state("reached", reply.goal_id)
        assert done.reason == ("run spot:teleop reached by an outcome not seen: spot:teleop ended while the monitor "
                               "was restarted: success confirmed by local")
        assert (done.commands, done.unknown, robot.actuator.sent.count("spot:teleop.start")) == (3, None, 1)
        again = ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="confirm", answer="success"))
        assert again.reason == "no goal is being followed: nothing to confirm"
    finally:
        impl.close()


@pytest.mark.parametrize("mode", ["standing", "fell"])
def test_an_outcome_the_resources_tell_is_inferred_and_the_pilot_goes_on(robot: Robot, mode: str) -> None:
    """stand_up's modes leave different postures: the pilot goes on from the inferred one, says so, and
    counts an inferred failure against the retries (it then stands up again, saying why)."""
    impl = World(robot.sim, script={("spot", "stand_up"): [mode]}, holding=[("spot", "stand_up")])
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive"))
        robot.statuses.first(lambda s: s.reason == "the outcome of spot:stand_up", what="stand_up running")
        restart_monitor_while(robot, impl, "stand_up")
        done = robot.statuses.state("reached", reply.goal_id)
        kind = "success" if mode == "standing" else "failure"
        note = f"spot:stand_up ended while the monitor was restarted: {kind}.{mode} inferred from the resources"
        assert done.notes == [note]
        if mode == "standing":
            assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:go_to_waypoint.start"]
            assert (done.retries, done.commands) == ({}, 3)
        else:
            assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.start",
                                           "spot:go_to_waypoint.start"]
            assert (done.retries, done.commands) == ({"spot:stand_up": 1}, 4)
    finally:
        impl.close()


def test_no_outcome_within_the_outcome_timeout_asks_the_manager_for_its_status(
        client_factory: Callable[[], zenoh.Session], spot_arm: tuple) -> None:
    robot = Robot(client_factory, *spot_arm, outcome_timeout=0.5)
    impl = World(robot.sim, holding=[("spot", "teleop")])
    topic = status_request_topic(robot.system.component("spot").skillset)
    try:
        ask_goal(robot.observer, goal("run spot:teleop", mode="drive"))
        robot.statuses.first(lambda s: s.reason == "the outcome of spot:teleop", what="teleop running")
        before = robot.sim.handled("spot", topic)
        waiting = robot.statuses.first(lambda s: "status asked" in s.reason, what="a status request")
        assert waiting.reason == ("the outcome of spot:teleop (none seen within 0.5 s: status asked of its manager: "
                                  "spot:teleop)")
        # the status is published under the pilot's lock, the request sent just after it: wait for the request
        wait_until(lambda: bool(robot.actuator.asked), 30.0, "the pilot's status request")
        assert set(robot.actuator.asked) == {"spot"}
        assert robot.sim.wait_handled("spot", topic, before + 1, timeout=30.0)
        assert robot.actuator.sent.count("spot:teleop.start") == 1
    finally:
        impl.close()
        robot.close()


def test_guide_mode_names_a_command_other_than_the_one_suggested(robot: Robot) -> None:
    gui = Gui(robot.observer, robot)
    try:
        reply = ask_goal(robot.observer, goal("run spot:stand_up"))
        robot.statuses.first(lambda s: s.next is not None and s.next.transition == "init_power.start")
        gui.start("manipulator", "arm_ready")
        told = robot.statuses.first(lambda s: bool(s.notes), what="a note")
        assert told.notes == ["the operator started manipulator:arm_ready, not spot:init_power: plan again"]
        assert (told.goal_id, told.mode, robot.actuator.sent) == (reply.goal_id, "guide", [])
        # the plan from the marking the operator caused: wait for arm_ready (the note stays in the status)
        assert (told.state, told.reason) == ("waiting for outcome", "the outcome of manipulator:arm_ready")
    finally:
        gui.close()


def test_an_outcome_lost_on_the_way_is_found_by_the_status_request(
        client_factory: Callable[[], zenoh.Session], spot_arm: tuple) -> None:
    """teleop ends on the robot but its response and status never leave the manager (a link down): the
    status request after the outcome timeout, or the bridge's own poll, whichever comes first, brings the status
    (test_no_outcome_within_the_outcome_timeout_asks_the_manager_for_its_status shows the first alone), and the
    pilot asks about the outcome."""
    robot = Robot(client_factory, *spot_arm, outcome_timeout=1.0)
    impl = World(robot.sim, holding=[("spot", "teleop")])
    try:
        ask_goal(robot.observer, goal("run spot:teleop", mode="drive"))
        robot.statuses.first(lambda s: s.reason == "the outcome of spot:teleop", what="teleop running")
        node = robot.sim.nodes["spot"]
        with node.lock:
            assert node.manager.terminate("teleop", "success", "done")  # its messages are lost
        paused = robot.statuses.first(lambda s: s.unknown is not None, what="an unknown outcome")
        # the gap in the pilot's words, or the monitor's when it lists the missed outcome itself
        assert paused.unknown is not None and (paused.unknown.skill, paused.unknown.candidates) == (
            "teleop", ["teleop.success.done", "teleop.failure.link_lost"]), paused.unknown
        assert robot.actuator.sent.count("spot:teleop.start") == 1
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="confirm", answer="rerun")).accepted
        again = robot.statuses.first(lambda s: s.commands == 4, what="teleop started again")
        assert again.notes[-1].endswith(": rerun confirmed by operator1")
        wait_until(lambda: robot.actuator.sent.count("spot:teleop.start") == 2, 30.0, "teleop sent again")
    finally:
        impl.close()
        robot.close()


def test_a_run_goal_is_reached_only_by_a_start_with_its_inputs(robot: Robot) -> None:
    """The operator walks spot elsewhere: the pilot names the start, does not count it, and suggests the
    goal's walk again."""
    impl = World(robot.sim)
    gui = Gui(robot.observer, robot)
    elsewhere = {"target": {"x": 1.0, "y": 2.0, "z": 0.0}}
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK))
        gui.start("spot", "init_power")
        robot.statuses.first(lambda s: s.next is not None and s.next.transition == "stand_up.start")
        gui.start("spot", "stand_up")
        robot.statuses.first(lambda s: s.next is not None and s.next.transition == "go_to_waypoint.start")
        gui.start("spot", "go_to_waypoint", elsewhere)
        told = robot.statuses.first(lambda s: bool(s.notes), what="a note")
        assert told.notes == ["spot:go_to_waypoint ended in success.arrived after a start with inputs "
                              "{'target': {'x': 1.0, 'y': 2.0, 'z': 0.0}}, not the goal's "
                              "{'target': {'x': 12.0, 'y': 3.5, 'z': 0.0}}: it does not count for "
                              "'run spot:go_to_waypoint'"]
        again = robot.statuses.first(lambda s: s.state == "guiding" and s.next is not None and
                                     s.next.transition == "go_to_waypoint.start" and bool(s.notes))
        assert (again.goal_id, again.next.inputs) == (reply.goal_id, WALK["go_to_waypoint"])
        gui.start("spot", "go_to_waypoint", WALK["go_to_waypoint"])
        done = robot.statuses.state("reached", reply.goal_id)
        assert (done.commands, robot.actuator.sent) == (0, [])
    finally:
        gui.close()
        impl.close()


def test_the_monitors_words_for_a_gap_are_quoted_in_the_pilots() -> None:
    from services.pilot.service import ended, unknown_reason

    monitor = MissedOutcome(skillset="spot", skill="teleop", gap="the link to manager /spot/spot_skillset_manager "
                                                                 "was down 12.4 s", candidates=["teleop.success.done"])
    assert ended(monitor) == ("spot:teleop ended unseen (the link to manager /spot/spot_skillset_manager was down "
                              "12.4 s)")
    assert unknown_reason(monitor.model_copy(update={"candidates": []})) == (
        "outcome unknown: spot:teleop ended unseen (the link to manager /spot/spot_skillset_manager was down 12.4 s); "
        "no outcome of the model explains the resources: confirm success, failure or rerun (the pilot does not "
        "start it again on its own)")
    assert ended(monitor.model_copy(update={"gap": "while the monitor was restarted"})) == (
        "spot:teleop ended while the monitor was restarted")
