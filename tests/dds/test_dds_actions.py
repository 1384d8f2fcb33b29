"""Bound skillsets over real DDS and the real zenoh-plugin-ros2dds (slow: cargo build; docs/semantics.md §9).

A CycloneDDS participant plays the Nav2 example's robot as rmw_cyclonedds lays it out
(:class:`services.simulator.dds_bound.DdsBoundRobot`: action servers as rq/rr service
topics with rmw_cyclonedds' request header and a transient-local status writer, a
lifecycle node with get_state, change_state and transition_event, the battery topic, and
``ros_discovery_info``).  The plugin routes them: action server routes (AS tokens,
send_goal/cancel_goal/get_result queryables, the status cached for late joiners),
service routes, topics.  The test's operator sends goals and cancels through the
plugin, as a remote client would, and so does the pilot's action client (docs/semantics.md §9,
*Acting*); the bridge derives the model's transitions.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
import zenoh

from event_watch import Events
from gateway import free_domain
from services.bridge_ros2.bound_live import start_bound_bridge
from services.common.zenoh_config import session_config
from services.pilot.errors import ActError
from services.pilot.bound_act import BoundActuator
from services.simulator.dds_bound import DdsBoundRobot
from skinet.system.load import load_bindings, load_system
from skinet.ros.actions import cancel_goal_reply, cancel_goal_request, send_goal_reply, send_goal_request
from skinet.ros.bound import goal_text
from skinet.ros.keys import KeyStyle
from skinet.wire.messages import PilotCommand

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
NAVIGATE = "nav2_msgs/action/NavigateToPose"


@pytest.fixture(scope="module")
def nav2():
    system, _ = load_system(REPO / "examples" / "nav2" / "nav2.toml")
    bindings, _ = load_bindings(system)
    return system, bindings


def client(endpoint: str) -> zenoh.Session:
    return zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))


def initial_status(robot: DdsBoundRobot, events: Events, battery: dict) -> object:
    """The battery publishes until the bridge's route exists (a volatile topic: samples before it are lost);
    the first event is then the initial status."""
    deadline = time.monotonic() + 20
    while not events.items and time.monotonic() < deadline:
        robot.publish("nav2", "/battery_state", battery)
        time.sleep(0.3)
    return events.wait(lambda items: len(items) >= 1)[0]


def call(session: zenoh.Session, key: str, payload: bytes, timeout: float = 10.0) -> bytes:
    """One service call through the plugin (retried until its route exists)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(key, payload=payload, timeout=2.0):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        time.sleep(0.2)
    raise AssertionError(f"no reply on {key}")


def behind_the_plugin(gateway_factory, system, bindings):  # type: ignore[no-untyped-def]
    """The Nav2 robot on DDS (jazzy) behind a gateway, with two client sessions (the bridge's and the pilot's),
    the bridge's events and the bridge."""
    domain = free_domain()
    gateway = gateway_factory(domain=domain, distro="jazzy")
    robot = DdsBoundRobot(system, bindings, domain=domain, distro="jazzy")
    session, pilot = client(gateway.endpoint), client(gateway.endpoint)
    events = Events(session, system.name)
    return robot, session, pilot, events, start_bound_bridge(session, system, bindings, settle=0.5, retry=0.3)


def send_when_routed(act: BoundActuator, transition: str, inputs: dict) -> str:
    """The actuator's command, sent again while no reply comes (until the plugin's route to the DDS server exists)."""
    deadline = time.monotonic() + 10
    while True:
        try:
            return act.send(PilotCommand(skillset="nav2", transition=transition, inputs=inputs))
        except ActError as exc:
            if "no reply" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.3)


@pytest.mark.parametrize("distro,namespace", [("jazzy", ""), ("humble", "/robot1")], ids=["jazzy", "humble-namespace"])
def test_a_nav2_run_on_dds_action_servers(gateway_factory, nav2, distro: str, namespace: str) -> None:
    system, bindings = nav2
    store = bindings["nav2"].store
    domain = free_domain()
    gateway = gateway_factory(domain=domain, distro=distro, namespace=namespace or "/")
    style = KeyStyle(namespace=namespace)
    robot = DdsBoundRobot(system, bindings, domain=domain, distro=distro)
    session = client(gateway.endpoint)
    events = Events(session, system.name)
    bridge = start_bound_bridge(session, system, bindings, style=style, settle=0.5, retry=0.3)
    try:
        first = initial_status(robot, events, {"percentage": 0.9, "power_supply_status": 1})
        assert (first.transition, first.info, first.status.running) == (None, "initial status", [])
        robot.lifecycle("nav2", "navigator", "Inactive")
        robot.lifecycle("nav2", "navigator", "Active")
        send = style.name_key("/undock_robot/_action/send_goal", "")
        goal = os.urandom(16)
        reply = call(session, send, send_goal_request(store, "opennav_docking_msgs/action/UndockRobot", goal))
        assert send_goal_reply(store, "opennav_docking_msgs/action/UndockRobot", reply)[0] is True
        assert robot.finish("nav2", "undock_robot", "success")
        robot.publish("nav2", "/battery_state", {"percentage": 0.9, "power_supply_status": 2})
        goal = os.urandom(16)
        nav = style.name_key("/navigate_to_pose/_action/send_goal", "")
        reply = call(session, nav, send_goal_request(store, NAVIGATE, goal, {"behavior_tree": "bt.xml"}))
        assert send_goal_reply(store, NAVIGATE, reply)[0] is True
        events.wait(lambda items: [e.transition for e in items][-1:] == ["navigate.start"], timeout=10)
        code, canceling = cancel_goal_reply(store, call(session, style.name_key(
            "/navigate_to_pose/_action/cancel_goal", ""), cancel_goal_request(store, goal)))
        assert (code, canceling) == ("ERROR_NONE", [goal])
        reply = call(session, nav, send_goal_request(store, NAVIGATE, os.urandom(16)))
        events.wait(lambda items: [e.transition for e in items][-1:] == ["navigate.start"], timeout=10)
        assert robot.finish("nav2", "navigate", "failure", {"error_code": 9003})  # get_result names the mode
        got = events.wait(lambda items: len(items) == 10, timeout=15)
    finally:
        bridge.close()
        robot.close()
        session.close()
    assert [e.transition for e in got] == [
        None, "navigator_configured", "navigator_activated", "undock_robot.start", "undock_robot.success.undocked",
        "charging_stopped", "navigate.start", "navigate.interrupt", "navigate.start", "navigate.failure.timed_out"]
    assert bridge.counters.drifts == 0 and bridge.counters.malformed == 0 and not bridge.counters.bad


def test_the_bridge_reads_a_busy_robot_at_start_up(gateway_factory, nav2) -> None:
    """A goal runs and the navigator is active before SkiNet starts: the last status comes from the
    plugin's cache of the transient-local topic, the navigator's state from get_state, through DDS."""
    system, bindings = nav2
    store = bindings["nav2"].store
    domain = free_domain()
    gateway = gateway_factory(domain=domain, distro="jazzy")
    robot = DdsBoundRobot(system, bindings, domain=domain, distro="jazzy")
    operator = client(gateway.endpoint)
    try:
        robot.lifecycle("nav2", "navigator", "Inactive")
        robot.lifecycle("nav2", "navigator", "Active")
        reply = call(operator, "navigate_to_pose/_action/send_goal", send_goal_request(store, NAVIGATE, os.urandom(16)))
        assert send_goal_reply(store, NAVIGATE, reply)[0]
        session = client(gateway.endpoint)
        events = Events(session, system.name)
        bridge = start_bound_bridge(session, system, bindings, settle=0.5, retry=0.3)
        try:
            first = initial_status(robot, events, {"percentage": 0.5, "power_supply_status": 2})
        finally:
            bridge.close()
            session.close()
    finally:
        robot.close()
        operator.close()
    assert first.info == "initial status"
    assert first.status.model_dump() == {
        "resources": {"navigator": "Active", "motion": "Still", "dock": "Docked", "battery": "Ok",
                      "charging": "NotCharging"}, "running": ["navigate"]}


def test_the_pilot_s_goals_and_cancel_requests_cross_the_plugin(gateway_factory, nav2) -> None:
    """docs/semantics.md §9, Acting: the pilot's BoundActuator, a Zenoh client behind the real plugin, sends the undocking and
    the docking goals (the binding's goal fields, the input at dock_id) to the DDS action servers, then cancels
    the docking goal it sent; the bridge derives start, success, start, interrupt."""
    system, bindings = nav2
    robot, session, pilot, events, bridge = behind_the_plugin(gateway_factory, system, bindings)
    act = BoundActuator(pilot, bindings, timeout=2.0)

    def send(transition: str, **inputs: str) -> str:
        return send_when_routed(act, transition, inputs)

    try:
        initial_status(robot, events, {"percentage": 0.9, "power_supply_status": 1})
        assert send("undock_robot.start").endswith(": accepted")
        events.wait(lambda items: [e.transition for e in items][-1:] == ["undock_robot.start"], timeout=10)
        assert robot.finish("nav2", "undock_robot", "success")
        events.wait(lambda items: [e.transition for e in items][-1:] == ["undock_robot.success.undocked"], timeout=10)
        sent = send("dock_robot.start", dock="home_dock")
        [(goal, fields)] = robot.actions[("nav2", "dock_robot")].received
        assert (fields["use_dock_id"], fields["dock_id"]) == (True, "home_dock") and goal.hex()[:8] in sent.replace(
            "-", "")
        events.wait(lambda items: [e.transition for e in items][-1:] == ["dock_robot.start"], timeout=10)
        assert send("dock_robot.interrupt").endswith("(the goal the pilot sent): canceling")
        events.wait(lambda items: [e.transition for e in items][-1:] == ["dock_robot.interrupt"], timeout=10)
        # An operator's goal: the pilot cancels the one the bridge follows, read from the plugin's status cache.
        theirs = os.urandom(16)
        call(session, "dock_robot/_action/send_goal", send_goal_request(
            bindings["nav2"].store, "opennav_docking_msgs/action/DockRobot", theirs))
        events.wait(lambda items: [e.transition for e in items][-1:] == ["dock_robot.start"], timeout=10)
        assert send("dock_robot.interrupt").endswith(f"goal {goal_text(theirs)} (the goal the bridge follows): "
                                                     "canceling")
        got = events.wait(lambda items: len(items) == 7, timeout=15)
    finally:
        bridge.close()
        robot.close()
        session.close()
        pilot.close()
    assert [e.transition for e in got] == [None, "undock_robot.start", "undock_robot.success.undocked",
                                           "dock_robot.start", "dock_robot.interrupt", "dock_robot.start",
                                           "dock_robot.interrupt"]
    assert bridge.counters.drifts == 0 and bridge.counters.malformed == 0 and not bridge.counters.bad


def test_the_pilot_s_lifecycle_transitions_cross_the_plugin(gateway_factory, nav2) -> None:
    """A commanded event through the real plugin: the pilot reads bt_navigator's state and calls its change_state
    (configure, then activate) on the DDS lifecycle node; the bridge derives both events from its TransitionEvents."""
    system, bindings = nav2
    robot, session, pilot, events, bridge = behind_the_plugin(gateway_factory, system, bindings)
    act = BoundActuator(pilot, bindings, timeout=2.0, skillsets={c.name: c.skillset for c in system.components})

    def send(transition: str) -> str:
        return send_when_routed(act, transition, {})

    try:
        initial_status(robot, events, {"percentage": 0.9, "power_supply_status": 1})
        assert send("navigator_configured") == (
            "change_state /bt_navigator configure (transition 1, unconfigured -> inactive): done")
        events.wait(lambda items: [e.transition for e in items][-1:] == ["navigator_configured"], timeout=10)
        assert send("navigator_activated") == (
            "change_state /bt_navigator activate (transition 3, inactive -> active): done")
        got = events.wait(lambda items: [e.transition for e in items][-1:] == ["navigator_activated"], timeout=10)
    finally:
        bridge.close()
        robot.close()
        session.close()
        pilot.close()
    assert [e.transition for e in got] == [None, "navigator_configured", "navigator_activated"]
    assert robot.lifecycles[("nav2", "navigator")].state == 3
