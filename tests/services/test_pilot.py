"""The pilot (SPEC §8, *The pilot*; issue 24) on the paper's robot through a real router: simulated
managers speaking the real protocol, the bridge, the monitor, a predictor and the pilot on their own
sessions; the skills' outcomes come from :class:`~tests.services.pilot_robot.Implementations`."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
import zenoh

from tests.services.pilot_robot import WALK, Implementations, Robot, ask_goal, goal


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
