"""The pilot acting through bindings (docs/semantics.md §9, *Acting*; services/pilot/bound_act.py).

Through a real router, each party on its own client session: the Nav2 example's
simulated robot (action servers speaking the real action protocol in CDR), the
bound bridge, and the actuator.  A start's goal reaches the action server with
the goal fields the binding maps from the inputs, the bridge reports the skill's
start; an interrupt cancels the goal and the bridge reports the interrupt; a goal
the server rejects, a goal with bad inputs, a missing server and an interrupt with
nothing to cancel are clear errors.  On zenoh-bridge-ros2dds keys (with and without
a namespace) and on rmw_zenoh keys.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from event_watch import Events
from services.bridge_ros2.bound_live import start_bound_bridge
from services.pilot.errors import ActError, Refused
from services.pilot.bound_act import BoundActuator
from services.simulator.bound import BoundSimulator
from skinet.system.load import load_bindings, load_system
from skinet.ros.keys import KeyStyle, parse_liveliness_token
from skinet.wire.messages import PilotCommand
from tests.services.conftest import wait_queryable

NAV2 = Path(__file__).resolve().parents[2] / "examples" / "nav2"
FIRST = {"/battery_state": {"percentage": 0.9, "power_supply_status": 2}, "/emergency_stop": {"data": False}}
STYLES = [KeyStyle(), KeyStyle(namespace="/robot1"), KeyStyle(rmw_zenoh=True, domain=7)]
IDS = ["zenoh-bridge-ros2dds", "namespace", "rmw_zenoh"]


@pytest.fixture(scope="module")
def nav2():
    system, _ = load_system(NAV2 / "nav2.toml")
    bindings, _ = load_bindings(system)
    return system, bindings


class Rig:
    """The robot, the bridge and an observer of its events, each on its own client session of the router."""

    def __init__(self, system, bindings, style: KeyStyle, open_: Callable[[], zenoh.Session]):  # type: ignore[no-untyped-def]
        self.robot = BoundSimulator(open_(), system, bindings, style=style)
        self.events = Events(open_(), system.name)
        self.bridge = start_bound_bridge(open_(), system, bindings, style=style, settle=0.1, retry=0.1)
        # A robot publishes its battery and e-stop topics again and again: until the bridge, whose subscriptions
        # may not have reached the router yet, has made its initial status from them.
        deadline = time.monotonic() + 20
        while True:
            self.robot.publish_topics(FIRST)
            if self.events.seen(lambda items: bool(items), 0.5) or time.monotonic() > deadline:
                break
        self.events.wait(lambda items: [e.info for e in items] == ["initial status"], timeout=5)

    def transitions(self) -> list[str | None]:
        return [e.transition for e in self.events.items]

    def wait_for(self, transition: str) -> None:
        self.events.wait(lambda items: transition in [e.transition for e in items], timeout=20)

    def received(self, skill: str) -> list[tuple[str, dict]]:
        """The goals the robot's action server of ``skill`` received: (goal id as ROS prints it, fields)."""
        return [(str(uuid.UUID(bytes=g)), fields) for g, fields in self.robot.actions[("nav2", skill)].logic.received]

    def close(self) -> None:
        self.bridge.close()
        self.robot.close()


@pytest.fixture
def rig(nav2, client_factory, request) -> Iterator[Rig]:  # type: ignore[no-untyped-def]
    system, bindings = nav2
    made = Rig(system, bindings, request.param, client_factory)
    yield made
    made.close()


def undocked(rig: Rig) -> None:
    """The navigator active, the robot off its dock (the operator's doing, through the simulated robot)."""
    for transition in ("navigator_configured", "navigator_activated", "undock_robot.start",
                       "undock_robot.success.undocked"):
        assert rig.robot.play("nav2", transition, None)
        rig.wait_for(transition)


@pytest.mark.parametrize("rig", STYLES, ids=IDS, indirect=True)
def test_a_start_sends_the_goal_and_an_interrupt_cancels_it(rig: Rig, nav2, client_factory) -> None:  # type: ignore[no-untyped-def]
    """dock_robot.start: a goal with the binding's fixed field and the input at its field; the bridge
    reports dock_robot.start; dock_robot.interrupt cancels that goal: the bridge reports the interrupt."""
    _, bindings = nav2
    undocked(rig)
    style = rig.bridge.style
    act = BoundActuator(client_factory(), bindings, style=style)
    sent = act.send(PilotCommand(skillset="nav2", transition="dock_robot.start", inputs={"dock": "home_dock"}))
    [(goal, fields)] = rig.received("dock_robot")
    assert sent == (f'send_goal /dock_robot goal {goal} {{"dock_id": "home_dock", "use_dock_id": true}}: accepted')
    assert {k: fields[k] for k in ("use_dock_id", "dock_id", "dock_type", "navigate_to_staging_pose")} == {
        "use_dock_id": True, "dock_id": "home_dock", "dock_type": "", "navigate_to_staging_pose": True}
    rig.wait_for("dock_robot.start")
    assert act.send(PilotCommand(skillset="nav2", transition="dock_robot.interrupt")) == (
        f"cancel_goal /dock_robot goal {goal} (the goal the pilot sent): canceling")
    rig.wait_for("dock_robot.interrupt")
    assert rig.transitions()[-2:] == ["dock_robot.start", "dock_robot.interrupt"]
    assert rig.events.items[-1].status.running == [] and rig.bridge.counters.drifts == 0


@pytest.mark.parametrize("rig", STYLES[:1] + STYLES[2:], ids=IDS[:1] + IDS[2:], indirect=True)
def test_an_interrupt_cancels_the_goal_the_bridge_follows_when_the_pilot_did_not_send_it(
        rig: Rig, nav2, client_factory) -> None:  # type: ignore[no-untyped-def]
    """The operator started the skill from their own client: the pilot cancels the goal that runs it."""
    _, bindings = nav2
    rig.robot.play("nav2", "undock_robot.start", None)
    rig.wait_for("undock_robot.start")
    [(goal, _)] = rig.received("undock_robot")
    act = BoundActuator(client_factory(), bindings, style=rig.bridge.style)
    assert act.send(PilotCommand(skillset="nav2", transition="undock_robot.interrupt")) == (
        f"cancel_goal /undock_robot goal {goal} (the goal the bridge follows): canceling")
    rig.wait_for("undock_robot.interrupt")
    # The goal has ended: another interrupt has nothing to cancel, and says what the status shows.
    with pytest.raises(ActError) as info:
        act.send(PilotCommand(skillset="nav2", transition="undock_robot.interrupt"))
    assert str(info.value) == (f"nav2:undock_robot: no goal of /undock_robot is active (its status shows "
                               f"{goal[:8]} CANCELED): nothing to cancel")


@pytest.mark.parametrize("rig", STYLES[:1], ids=IDS[:1], indirect=True)
def test_a_rejected_goal_is_an_error_and_starts_nothing(rig: Rig, nav2, client_factory) -> None:  # type: ignore[no-untyped-def]
    _, bindings = nav2
    server = rig.robot.actions[("nav2", "undock_robot")].logic
    server.accepting = False
    act = BoundActuator(client_factory(), bindings)
    with pytest.raises(ActError) as info:
        act.send(PilotCommand(skillset="nav2", transition="undock_robot.start"))
    [(goal, _)] = rig.received("undock_robot")
    assert str(info.value) == (f'send_goal /undock_robot goal {goal} {{}}: the action server of /undock_robot '
                               "rejected the goal")
    assert isinstance(info.value, Refused)  # nothing changed on the robot: the pilot may ask again
    assert server.goals == {} and rig.bridge.wait_idle() and rig.transitions() == [None]
    # Its server takes goals again: the same command is accepted.
    server.accepting = True
    assert act.send(PilotCommand(skillset="nav2", transition="undock_robot.start")).endswith(": accepted")
    rig.wait_for("undock_robot.start")


def test_bad_commands_are_clear_errors_and_send_nothing(nav2, client_factory) -> None:  # type: ignore[no-untyped-def]
    """Inputs the skill does not have or whose type does not fit the goal, a skill bound to no action, an
    action server that does not answer or whose reply does not decode, an interrupt with no goal."""
    system, bindings = nav2
    robot = BoundSimulator(client_factory(), system, bindings)
    pilot_side = client_factory()
    act = BoundActuator(pilot_side, bindings, timeout=0.5)
    cases = [
        (PilotCommand(skillset="nav2", transition="dock_robot.start", inputs={"target": "home"}),
         "nav2:dock_robot: 'target' is not an input of dock_robot"),
        (PilotCommand(skillset="nav2", transition="dock_robot.start", inputs={"dock": 3}),
         "nav2:dock_robot: the goal of /dock_robot cannot be sent: expected string at dock_id, got an integer"),
        (PilotCommand(skillset="nav2", transition="launch.start"),
         "nav2:launch is bound to no action (its skillset has no manager either: the pilot cannot command it)"),
        (PilotCommand(skillset="base", transition="dock_robot.start"), "base:dock_robot is bound to no action"),
        (PilotCommand(skillset="nav2", transition="dock_robot.success"),
         "nav2:dock_robot.success is not a command (SKILL.start or SKILL.interrupt)"),
        (PilotCommand(skillset="nav2", transition="navigate.interrupt"),
         "nav2:navigate: no goal of /navigate_to_pose is active (its status shows no goal): nothing to cancel"),
    ]
    for command, reason in cases:
        with pytest.raises(ActError) as info:
            act.send(command)
        assert str(info.value) == reason
    assert all(not server.logic.received for server in robot.actions.values())
    robot.close()  # no action server any more
    with pytest.raises(ActError) as info:
        act.send(PilotCommand(skillset="nav2", transition="undock_robot.start"))
    assert str(info.value).endswith(": no reply from the action server of /undock_robot within 0.5 s")
    # A server whose replies do not decode.
    junk = client_factory().declare_queryable("undock_robot/_action/send_goal",
                                              lambda q: q.reply(q.key_expr, b"\x00\x01\x00"))
    wait_queryable(pilot_side, "undock_robot/_action/send_goal")  # the junk server's own session
    with pytest.raises(ActError) as info:
        act.send(PilotCommand(skillset="nav2", transition="undock_robot.start"))
    assert "the reply of /undock_robot does not decode: " in str(info.value)
    junk.undeclare()


@pytest.mark.parametrize("rig", STYLES[:1], ids=IDS[:1], indirect=True)
def test_the_simulated_robot_ends_the_goals_it_accepted(rig: Rig, nav2, client_factory) -> None:  # type: ignore[no-untyped-def]
    """Without a scenario, ``on_start`` hears of each goal an action server accepts and ``terminate`` ends that
    goal in a mode: what a pilot acting through the bindings needs from the simulated robot."""
    _, bindings = nav2
    started: list[tuple[str, str, str]] = []
    rig.robot.on_start.append(lambda *args: started.append(args))
    undocked(rig)
    act = BoundActuator(client_factory(), bindings)
    act.send(PilotCommand(skillset="nav2", transition="dock_robot.start", inputs={"dock": "d1"}))
    [(goal, _)] = rig.received("dock_robot")
    assert started == [("nav2", "undock_robot", rig.received("undock_robot")[0][0]), ("nav2", "dock_robot", goal)]
    with pytest.raises(ValueError, match="^nav2:dock_robot: no result found that names the failure mode stuck "
                                         r"\(not the binding's default, failed\): give the result's fields$"):
        rig.robot.terminate("nav2", "dock_robot", "failure", "stuck", goal)
    assert not rig.robot.terminate("nav2", "dock_robot", "success", "docked", rig.received("undock_robot")[0][0])
    # A mode the binding names by a condition on the result: the result that makes it true (error_code 906).
    assert rig.robot.terminate("nav2", "dock_robot", "failure", "not_charging", goal)
    rig.wait_for("dock_robot.failure.not_charging")
    assert rig.events.items[-1].status.resources["dock"] == "Docked"


def test_on_rmw_zenoh_the_actuator_shows_as_an_action_client_in_the_ros_graph(nav2, client_factory) -> None:  # type: ignore[no-untyped-def]
    """rmw_zenoh's graph tokens: a node with a service client of each action's send_goal and cancel_goal, gone
    when the actuator closes."""
    _, bindings = nav2
    observer = client_factory()

    def graph() -> set[tuple[str, str, str]]:
        found = {parse_liveliness_token(str(r.ok.key_expr)) for r in observer.liveliness().get("@ros2_lv/9/**",
                                                                                               timeout=2.0) if r.ok}
        return {(e.node, e.kind, e.topic) for e in found if e is not None and e.node.startswith("skinet_pilot_")}

    def settled(expected: int) -> set[tuple[str, str, str]]:
        deadline = time.monotonic() + 10  # declarations and undeclarations cross the router
        while len(got := graph()) != expected and time.monotonic() < deadline:
            time.sleep(0.05)
        return got

    act = BoundActuator(client_factory(), bindings, style=KeyStyle(rmw_zenoh=True, domain=9))
    got = settled(7)
    node = next(iter(got))[0]
    assert got == {(node, "NN", "")} | {(node, "SC", f"/{action}/_action/{service}")
                                        for action in ("navigate_to_pose", "dock_robot", "undock_robot")
                                        for service in ("send_goal", "cancel_goal")}
    act.close()
    assert settled(0) == set()


@pytest.mark.parametrize("rig", STYLES, ids=IDS, indirect=True)
def test_a_commanded_event_is_the_lifecycle_transition_to_its_state(rig: Rig, nav2, client_factory) -> None:  # type: ignore[no-untyped-def]
    """bt_navigator is commanded: navigator_configured and navigator_activated are change_state calls with the
    transitions configure and activate, read from the node's state; the bridge reports each event.  An event
    whose guard the node's state no longer satisfies is refused, and the node stays as it is."""
    system, bindings = nav2
    act = BoundActuator(client_factory(), bindings, style=rig.bridge.style,
                        skillsets={c.name: c.skillset for c in system.components})
    node = rig.robot.nodes[("nav2", "navigator")].logic
    with pytest.raises(Refused) as info:
        act.send(PilotCommand(skillset="nav2", transition="navigator_activated"))
    assert str(info.value) == ("nav2:navigator_activated: /bt_navigator is unconfigured, where navigator_activated "
                               "cannot happen (navigator must be Inactive)")
    assert node.state == 1
    assert act.send(PilotCommand(skillset="nav2", transition="navigator_configured")) == (
        "change_state /bt_navigator configure (transition 1, unconfigured -> inactive): done")
    rig.wait_for("navigator_configured")
    assert act.send(PilotCommand(skillset="nav2", transition="navigator_activated")) == (
        "change_state /bt_navigator activate (transition 3, inactive -> active): done")
    rig.wait_for("navigator_activated")
    assert node.state == 3 and rig.transitions() == [None, "navigator_configured", "navigator_activated"]
    assert rig.events.items[-1].status.resources["navigator"] == "Active"
    assert act.send(PilotCommand(skillset="nav2", transition="navigator_shut_down")) == (
        "change_state /bt_navigator active_shutdown (transition 7, active -> finalized): done")
    rig.wait_for("navigator_shut_down")


def test_a_commanded_topic_resource_is_sent_only_when_its_binding_names_one_message(
        tmp_path: Path, client_factory) -> None:  # type: ignore[no-untyped-def]
    """A commanded resource on a topic: the pilot publishes the message its state's condition pins
    (``data`` for On), and refuses a state whose condition leaves a choice (``percentage < 0.2``)."""
    binding = (NAV2 / "nav2.binding.toml").read_text().replace(
        'states = { Low = "percentage < 0.2", Ok = "percentage >= 0.2" }',
        'states = { Low = "percentage < 0.2", Ok = "percentage >= 0.2" }\ncommanded = true')
    binding = binding.replace('[resources.navigator]', '[resources.motion]\ntopic = "/motion"\n'
                              'type = "std_msgs/msg/Bool"\nstates = { Moving = "data", Still = "not data" }\n'
                              'commanded = true\n\n[resources.navigator]')
    binding = binding[:binding.index("[events.emergency_stop]")]  # the stop is now a command, no longer seen
    (tmp_path / "nav2.binding.toml").write_text(binding)
    (tmp_path / "interfaces").symlink_to(NAV2 / "interfaces")
    (tmp_path / "s.toml").write_text(
        f'[system]\nname = "nav2"\nproperties = "{NAV2 / "nav2.props"}"\n[[skillsets]]\nmodel = "{NAV2 / "nav2.rl"}"\n'
        'binding = "nav2.binding.toml"\n')
    system, _ = load_system(tmp_path / "s.toml")
    bindings, _ = load_bindings(system)
    watcher = client_factory()
    seen: list[bytes] = []
    sub = watcher.declare_subscriber("motion", lambda sample: seen.append(sample.payload.to_bytes()))
    act = BoundActuator(client_factory(), bindings, skillsets={c.name: c.skillset for c in system.components})
    with pytest.raises(ActError) as info:
        act.send(PilotCommand(skillset="nav2", transition="battery_low"))
    assert str(info.value) == ("nav2:battery_low cannot be sent: the binding maps battery Low to 'percentage < 0.2' "
                               "on /battery_state, which names no single message to publish")
    with pytest.raises(ActError) as info:
        act.send(PilotCommand(skillset="nav2", transition="charging_started"))
    assert str(info.value) == ("nav2:charging_started is an event its binding does not command (the robot's own): "
                               "the pilot cannot send it")
    deadline = time.monotonic() + 20
    while not seen and time.monotonic() < deadline:  # until the subscription has reached the router
        assert act.send(PilotCommand(skillset="nav2", transition="emergency_stop")) == 'publish /motion {"data": false}'
        time.sleep(0.05)
    assert seen and seen[-1] == bytes([0, 1, 0, 0, 0])  # CDR little endian, data false
    sub.undeclare()
