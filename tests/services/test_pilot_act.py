"""How the pilot acts (services/pilot/act.py): each skill's route, and what happens to a command no
actuator of the pilot can carry."""

from __future__ import annotations

import pytest

from services.pilot import ActError, Routed, route
from skinet.system.load import load_system
from skinet.wire.messages import PilotCommand
from tests.services.conftest import REPO


class Kept:
    """An actuator that keeps what it is given (to see where a command is routed)."""

    def __init__(self) -> None:
        self.sent: list[PilotCommand] = []
        self.closed = False

    def send(self, command: PilotCommand) -> str:
        self.sent.append(command)
        return command.transition

    def close(self) -> None:
        self.closed = True


def test_skills_of_managers_and_of_bindings_take_their_own_route() -> None:
    paper, _ = load_system(REPO / "skillsets" / "spot_arm.toml")
    nav2, _ = load_system(REPO / "examples" / "nav2" / "nav2.toml")
    assert route(paper, "spot", "init_power") == "manager"
    assert route(nav2, "nav2", "navigate") == "binding"
    managers = Kept()
    routed = Routed(nav2, {"manager": managers})
    with pytest.raises(ActError, match=r"^nav2:navigate is bound to a ROS 2 interface \(docs/semantics.md §9\), and this pilot "
                                       r"cannot act through bindings$"):
        routed.send(PilotCommand(skillset="nav2", transition="navigate.start"))
    with pytest.raises(ActError, match=r"^unknown skillset 'spot' of nav2$"):
        routed.send(PilotCommand(skillset="spot", transition="init_power.start"))
    bindings = Kept()
    both = Routed(nav2, {"manager": managers, "binding": bindings})
    assert both.send(PilotCommand(skillset="nav2", transition="dock_robot.start")) == "dock_robot.start"
    assert ([c.transition for c in bindings.sent], managers.sent) == (["dock_robot.start"], [])
    both.close()
    assert managers.closed and bindings.closed
