"""The pilot (SPEC §8, *The pilot*; issue 24) on the paper's robot through a real router: simulated
managers speaking the real protocol, the bridge, the monitor, a predictor and the pilot on their own
sessions; the skills' outcomes come from :class:`~tests.services.pilot_robot.Implementations`."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
import zenoh

from tests.services.pilot_robot import WALK, Gui, Implementations, Robot, ask_goal, goal


# `skinet plan skillsets/spot_arm.toml "reach manipulator:RD" "run spot:go_to_waypoint"`, outcomes favourable.
MISSION = ["manipulator:arm_ready.start", "spot:init_power.start", "spot:stand_up.start",
           "manipulator:arm_RD_to_HP.start", "spot:go_to_waypoint.start"]
ENDS = ["ready", "powered_on", "standing", "at_home", "arrived"]


@pytest.fixture
def robot(client_factory: Callable[[], zenoh.Session], spot_arm: tuple) -> Iterator[Robot]:
    r = Robot(client_factory, *spot_arm)
    yield r
    r.close()


def test_drive_reaches_a_mission_with_exactly_the_planned_commands(robot: Robot) -> None:
    system = robot.system
    impl = Implementations(robot.sim, system)
    try:
        reply = ask_goal(robot.observer, goal("reach manipulator:RD", "run spot:go_to_waypoint", inputs=WALK,
                                              mode="drive"))
        assert (reply.accepted, reply.reason, reply.goal_id, reply.answer, reply.moves) == (True, "", 1, "cyclic", 2)
        done = robot.statuses.state("reached", 1)
        assert robot.actuator.sent == MISSION
        assert robot.actuator.inputs[-1] == {"target": {"x": 12.0, "y": 3.5, "z": 0.0}}
        assert (done.commands, done.denied, done.retries, done.index, done.next) == (5, 0, {}, 1, None)
        assert impl.ended == [f"{c.removesuffix('.start')}.success.{m}" for c, m in zip(MISSION, ENDS)]
    finally:
        impl.close()


def test_guide_sends_nothing_and_publishes_the_exact_next_command(robot: Robot) -> None:
    impl = Implementations(robot.sim, robot.system)
    gui = Gui(robot.observer, robot)
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK))
        assert (reply.accepted, reply.answer, reply.moves) == (True, "cyclic", 6)
        assert [(s.number, s.skillset, s.action, s.expect) for s in reply.steps[:2]] == [
            ("1", "spot", "init_power.start", None), ("2", "spot", "wait", "init_power.success.powered_on")]
        first = robot.statuses.wait(lambda s: s.state == "guiding" and s.next is not None)
        assert (first.next.skillset, first.next.transition, first.next.inputs, first.mode) == (
            "spot", "init_power.start", {}, "guide")
        assert (first.answer, first.moves_left, first.goals) == ("cyclic", 6, ["run spot:go_to_waypoint"])
        gui.start("spot", "init_power")  # the operator follows the guide
        after = robot.statuses.wait(lambda s: s.next is not None and s.next.transition == "stand_up.start")
        assert (after.state, after.moves_left) == ("guiding", 4)
        gui.start("spot", "stand_up")
        walk = robot.statuses.wait(lambda s: s.next is not None and s.next.transition == "go_to_waypoint.start")
        assert walk.next.inputs == WALK["go_to_waypoint"]
        gui.start("spot", "go_to_waypoint", WALK["go_to_waypoint"])
        done = robot.statuses.state("reached", reply.goal_id)
        assert (robot.actuator.sent, done.commands, done.denied) == ([], 0, 0)
    finally:
        gui.close()
        impl.close()


def test_the_operator_acts_and_the_pilot_plans_again_from_what_they_caused(robot: Robot) -> None:
    """Spot is standing up (held) when the operator interrupts it: the pilot plans again from there
    and stands it up again; an interrupt is no failure."""
    impl = Implementations(robot.sim, robot.system, hold=[("spot", "stand_up")])
    gui = Gui(robot.observer, robot)
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive"))
        robot.statuses.wait(lambda s: s.reason == "the outcome of spot:stand_up")  # the pilot saw it start
        gui.interrupt("spot", "stand_up")
        robot.statuses.wait(lambda s: s.commands == 3, what="a third command")
        impl.release("spot", "stand_up")
        done = robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.start",
                                       "spot:go_to_waypoint.start"]
        assert (done.commands, done.denied, done.retries) == (4, 0, {})
    finally:
        gui.close()
        impl.close()


def test_a_failed_skill_is_retried(robot: Robot) -> None:
    impl = Implementations(robot.sim, robot.system, {("spot", "stand_up"): ["fell"]})
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive"))
        done = robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.start",
                                       "spot:go_to_waypoint.start"]
        assert (done.retries, done.commands) == ({"spot:stand_up": 1}, 4)
    finally:
        impl.close()


def test_max_retries_failures_of_one_skill_end_the_goal_with_skill_and_mode(robot: Robot) -> None:
    impl = Implementations(robot.sim, robot.system, {("spot", "stand_up"): ["fell", "fell"]})
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive", max_retries=2))
        done = robot.statuses.state("failed", reply.goal_id)
        assert done.reason == "spot:stand_up failed 2 times (last: fell)"
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.start"]
        assert (done.retries, done.next) == ({"spot:stand_up": 2}, None)
    finally:
        impl.close()
