"""The pilot drives a robot without skillset managers through its bindings (docs/semantics.md §8, §9 *Acting*; issue 26 item 4).

The Nav2 example through a real router, each party on its own client session: the
simulated robot (action servers, bt_navigator's lifecycle and the battery topic in CDR),
the bound bridge, the monitor, a predictor and the pilot with its default actuator.  The
robot ends each goal it accepts in its success mode, as Nav2's servers would.  A goal
`run nav2:dock_robot` from the dock, in drive mode, is reached by exactly two action
goals (undock, then dock with the goal's input at the binding's field); guide mode
sends none; a goal the server rejects ends the pilot's goal with the server's reason.
`skinet demo nav2` ends with the pilot docking the robot through the binding.
"""

from __future__ import annotations

import re
import subprocess
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from event_watch import Events
from services.bridge_ros2.bound_live import start_bound_bridge
from services.monitor import start_monitor
from services.pilot import start_pilot
from services.pilot.act import default_actuator
from services.predictor.service import start_predictor
from services.simulator.bound import BoundSimulator
from services.simulator.protocols import ActionLogic
from services.simulator.world import World
from skinet.system.load import load_bindings, load_system
from skinet.ros.keys import KeyStyle
from skinet_cli.main import main
from tests.services.conftest import wait_queryable
from tests.services.test_monitor import wait_until
from tests.services.pilot_robot import Recording, Statuses, ask_goal, goal, matched_statuses, wait_pilot

NAV2 = Path(__file__).resolve().parents[2] / "examples" / "nav2"
FIRST = {"/battery_state": {"percentage": 0.15, "power_supply_status": 2}, "/emergency_stop": {"data": False}}
DOCK = {"dock_robot": {"dock": "home_dock"}}


class Nav2:
    """Robot, bridge, monitor, predictor and pilot of the Nav2 example, each on its own client session."""

    def __init__(self, sessions: Callable[[], zenoh.Session], style: KeyStyle, end_goals: bool = True,
                 pilot: bool = True, response_timeout: float = 5.0):
        self.system, _ = load_system(NAV2 / "nav2.toml")
        self.bindings, _ = load_bindings(self.system)
        self.robot = BoundSimulator(sessions(), self.system, self.bindings, style=style)
        # the robot's implementation: each accepted goal succeeds a moment later
        self.world = World(self.robot, duration=0.05) if end_goals else None
        self.bridge = start_bound_bridge(sessions(), self.system, self.bindings, style=style, settle=0.1, retry=0.1)
        self.predictor = start_predictor(sessions(), "bound-pilot-test")
        self.monitor = start_monitor(sessions(), self.system)
        self.pilot = None
        if pilot:  # else a pilot process of the test's
            pilot_session = sessions()
            self.actuator = Recording(default_actuator(pilot_session, self.system, style=style))  # type: ignore[arg-type]
            self.pilot = start_pilot(pilot_session, self.system, instance="p1", actuator=self.actuator,
                                     response_timeout=response_timeout, memory_limit=None)  # see pilot_robot.Robot
        self.observer = sessions()
        self.statuses = Statuses(self.observer, "nav2") if self.pilot is None else matched_statuses(
            self.observer, self.pilot, "nav2")
        self.events = Events(self.observer, "nav2")
        self.robot.publish_topics(FIRST)

    def received(self) -> list[tuple[str, str, dict]]:
        """Every goal the robot's action servers received, in order: (skill, goal id, fields)."""
        got = [(server.logic.received, skill) for (_, skill), server in self.robot.actions.items()]
        return [(skill, str(uuid.UUID(bytes=g)), f) for received, skill in got for g, f in received]

    def close(self) -> None:
        if self.pilot is not None:
            self.pilot.close()
        if self.world is not None:
            self.world.close()
        self.monitor.close()
        self.bridge.close()
        self.predictor.close()
        self.robot.close()


@pytest.fixture
def nav2(client_factory: Callable[[], zenoh.Session], request: pytest.FixtureRequest) -> Iterator[Nav2]:
    style, end_goals = getattr(request, "param", (KeyStyle(), True))
    rig = Nav2(client_factory, style, end_goals)
    wait_pilot(rig.pilot, "idle")
    yield rig
    rig.close()


@pytest.mark.parametrize("nav2", [(KeyStyle(), True), (KeyStyle(rmw_zenoh=True, domain=3), True)],
                         ids=["zenoh-bridge-ros2dds", "rmw_zenoh"], indirect=True)
def test_drive_docks_through_the_action_servers(nav2: Nav2) -> None:
    """From the dock, `run nav2:dock_robot`: undock, then dock with the goal's input at dock_id; reached."""
    reply = ask_goal(nav2.observer, goal("run nav2:dock_robot", system="nav2", inputs=DOCK, mode="drive"),
                     system="nav2")
    # As `skinet plan examples/nav2/nav2.toml "run nav2:dock_robot"` gives it: undock first, retry on failure.
    assert (reply.accepted, reply.reason, reply.answer, reply.moves) == (True, "", "cyclic", 4)
    assert [(s.action, s.expect, s.inputs) for s in reply.steps] == [
        ("undock_robot.start", None, None), ("wait", "undock_robot.success.undocked", None),
        ("dock_robot.start", None, {"dock": "home_dock"}), ("wait", "dock_robot.success.docked", None)]
    done = nav2.statuses.state("reached", reply.goal_id)
    assert (done.commands, done.denied, done.retries) == (2, 0, {})
    assert nav2.actuator.sent == ["nav2:undock_robot.start", "nav2:dock_robot.start"]
    [(undock, undock_id, undock_goal), (dock, dock_id, dock_goal)] = sorted(
        nav2.received(), key=lambda r: r[0] != "undock_robot")
    # The fields the plan does not give have their definitions' defaults, as rosidl gives them: Nav2 would time an
    # undocking out at once with 0 s, and a quaternion of zeros is no rotation.
    assert (undock, undock_goal) == ("undock_robot", {"dock_type": "", "max_undocking_time": 30.0})
    zero = {"x": 0.0, "y": 0.0, "z": 0.0}
    assert (dock, dock_goal) == ("dock_robot", {  # the binding's fixed field, the input at dock_id, defaults
        "use_dock_id": True, "dock_id": "home_dock", "dock_type": "", "max_staging_time": 1000.0,
        "navigate_to_staging_pose": True,
        "dock_pose": {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
                      "pose": {"position": zero, "orientation": {**zero, "w": 1.0}}}})
    assert nav2.world is not None
    wait_until(lambda: len(nav2.world.ends) == 2, 10, "both ends")  # the pilot may see them before terminate returns
    assert [(e.skill, e.id, e.kind, e.ok) for e in nav2.world.ends] == [("undock_robot", undock_id, "success", True),
                                                                      ("dock_robot", dock_id, "success", True)]
    transitions = [e.transition for e in nav2.events.wait(lambda items: len(items) >= 5, timeout=20)]
    assert transitions == [None, "undock_robot.start", "undock_robot.success.undocked", "dock_robot.start",
                           "dock_robot.success.docked"]
    assert nav2.events.items[-1].status.resources["dock"] == "Docked"


@pytest.mark.parametrize("nav2", [(KeyStyle(), True), (KeyStyle(rmw_zenoh=True, domain=3), True)],
                         ids=["zenoh-bridge-ros2dds", "rmw_zenoh"], indirect=True)
def test_drive_activates_the_commanded_navigator_then_navigates(nav2: Nav2) -> None:
    """bt_navigator is commanded (nav2.binding.toml): from an inactive navigator, `run nav2:navigate` activates it
    through its change_state service, then navigates; reached, the node active (docs/robot.md)."""
    nav2.robot.publish_topics({"/battery_state": {"percentage": 0.9, "power_supply_status": 2}})
    nav2.robot.lifecycle("nav2", "navigator", "Inactive")
    # Guided first, asked again at each new live state of the pilot's until it has both changes (before, the
    # battery is low and no plan navigates): its first step is then the activation.
    deadline = time.monotonic() + 30
    while True:
        guide = ask_goal(nav2.observer, goal("run nav2:navigate", system="nav2", replace=True), system="nav2")
        if guide.accepted and guide.steps and guide.steps[0].action == "navigator_activated":
            break
        assert time.monotonic() < deadline, guide
        last = max((st.state_seq for st in nav2.statuses.items), default=0)
        nav2.statuses.seen(lambda items: any(st.state_seq > last for st in items), 5)
    assert nav2.actuator.sent == []
    reply = ask_goal(nav2.observer, goal("run nav2:navigate", system="nav2", mode="drive", replace=True),
                     system="nav2")
    assert (reply.accepted, reply.reason, reply.answer) == (True, "", "cyclic")
    assert [(s.action, s.expect) for s in reply.steps] == [  # docked but not charging: it may leave the dock
        ("navigator_activated", None), ("navigate.start", None), ("wait", "navigate.success.arrived")]
    done = nav2.statuses.state("reached", reply.goal_id)
    assert (done.commands, done.denied, done.retries) == (2, 0, {})
    assert nav2.actuator.sent == ["nav2:navigator_activated", "nav2:navigate.start"]
    assert nav2.robot.nodes[("nav2", "navigator")].logic.state == 3  # active
    assert [skill for skill, _, _ in nav2.received()] == ["navigate"]
    transitions = [e.transition for e in nav2.events.of("nav2")]
    assert transitions[-3:] == ["navigator_activated", "navigate.start", "navigate.success.arrived"]


@pytest.mark.parametrize("nav2", [(KeyStyle(), True)], ids=["zenoh-bridge-ros2dds"], indirect=True)
def test_an_input_the_goal_message_cannot_hold_is_refused_before_the_robot_moves(nav2: Nav2) -> None:
    """The model does not say what a DockId is; the binding does (dock_id, a string).  A goal whose input the
    goal message cannot hold is rejected when it is given, not after the pilot undocked the robot for it."""
    reply = ask_goal(nav2.observer, goal("run nav2:dock_robot", system="nav2", inputs={"dock_robot": {"dock": 3}},
                                         mode="drive"), system="nav2")
    assert (reply.accepted, reply.reason) == (False, "'run nav2:dock_robot': nav2:dock_robot: the goal of /dock_robot "
                                                     "cannot be sent: expected string at dock_id, got an integer")
    time.sleep(0.5)
    assert nav2.actuator.sent == [] and nav2.received() == []


@pytest.mark.parametrize("nav2", [(KeyStyle(), False)], ids=["robot-idle"], indirect=True)
def test_guide_sends_no_goal_and_rejected_goals_are_asked_again_then_fail_the_goal(nav2: Nav2) -> None:
    reply = ask_goal(nav2.observer, goal("run nav2:dock_robot", system="nav2", inputs=DOCK), system="nav2")
    guiding = nav2.statuses.first(lambda s: s.goal_id == reply.goal_id and s.state == "guiding")
    assert (guiding.next.skillset, guiding.next.transition) == ("nav2", "undock_robot.start")
    assert nav2.received() == [] and nav2.actuator.sent == []
    # Drive: the undocking server refuses goals.  Nothing changed on the robot: the pilot pauses with the
    # server's reason and asks again, a new goal each time, until max_retries refusals end the goal.
    nav2.robot.actions[("nav2", "undock_robot")].logic.accepting = False
    reply = ask_goal(nav2.observer, goal("run nav2:dock_robot", system="nav2", inputs=DOCK, mode="drive",
                                         replace=True, max_retries=2), system="nav2")
    failed = nav2.statuses.state("failed", reply.goal_id)
    [(_, first, _), (_, second, _)] = nav2.received()
    rejected = "send_goal /undock_robot goal {} {{}}: the action server of /undock_robot rejected the goal"
    paused = nav2.statuses.first(lambda s: s.goal_id == reply.goal_id and s.state == "paused")
    assert (paused.reason, failed.reason) == (rejected.format(first), f"{rejected.format(second)} (2 times)")
    assert first != second and nav2.robot.actions[("nav2", "undock_robot")].logic.goals == {}


def test_an_action_server_that_accepts_and_then_says_nothing_fails_the_goal(
        client_factory: Callable[[], zenoh.Session]) -> None:
    """A stuck server: it accepts the goal, and no status ever shows it.  The goal fails naming that server."""
    rig = Nav2(client_factory, KeyStyle(), response_timeout=1.0)
    try:
        wait_pilot(rig.pilot, "idle")
        rig.robot.actions[("nav2", "undock_robot")].close()  # its queryables go; a stuck one takes its place
        stuck = ActionLogic(rig.bindings["nav2"].store, rig.bindings["nav2"].skill("undock_robot").type)
        server = client_factory().declare_queryable(
            "undock_robot/_action/send_goal", lambda q: q.reply(q.key_expr, stuck.send_goal(q.payload.to_bytes())[0]))
        wait_queryable(rig.observer, "undock_robot/_action/send_goal")
        reply = ask_goal(rig.observer, goal("run nav2:dock_robot", system="nav2", inputs=DOCK, mode="drive"),
                         system="nav2")
        failed = rig.statuses.state("failed", reply.goal_id)
        assert failed.reason == ("no response from the action server of nav2:undock_robot within 1 s to "
                                 "nav2:undock_robot.start")
        assert len(stuck.received) == 1 and rig.actuator.sent == ["nav2:undock_robot.start"]
        server.undeclare()
    finally:
        rig.close()


def test_the_pilot_process_acts_on_rmw_zenoh_keys(client_factory: Callable[[], zenoh.Session], zenoh_args: list[str],
                                                  spawn: Callable[..., subprocess.Popen]) -> None:
    """``python -m services.pilot nav2.toml --rmw-zenoh --domain 4``: its goals reach the action servers on rmw_zenoh
    keys (the robot, bridge and monitor of the test speak them too)."""
    rig = Nav2(client_factory, KeyStyle(rmw_zenoh=True, domain=4), pilot=False)
    try:
        spawn("services.pilot", str(NAV2 / "nav2.toml"), "--rmw-zenoh", "--domain", "4", "--instance", "proc",
              *zenoh_args)
        rig.statuses.first(lambda s: s.pilot == "proc" and s.state == "idle", 30, "'idle' of the pilot process")
        reply = ask_goal(rig.observer, goal("run nav2:dock_robot", system="nav2", inputs=DOCK, mode="drive"),
                         system="nav2")
        done = rig.statuses.state("reached", reply.goal_id, timeout=30)
        assert (done.commands, done.denied) == (2, 0)
        assert [(skill, {k: fields[k] for k in ("dock_id",) if k in fields}) for skill, _, fields in sorted(
            rig.received(), key=lambda r: r[0] != "undock_robot")] == [
            ("undock_robot", {}), ("dock_robot", {"dock_id": "home_dock"})]
    finally:
        rig.close()


def test_skinet_demo_nav2_ends_with_the_pilot_docking(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 26 item 5: after the run in which the check warns twice, the pilot docks through the binding: one
    goal to the docking server with the goals file's input at dock_id, the robot docked, nothing violated."""
    assert main(["demo", "nav2"]) == 0
    out = capsys.readouterr().out.splitlines()
    dock = NAV2 / "missions" / "dock.toml"
    at = next(n for n, line in enumerate(out) if line.startswith("   then the pilot"))
    assert out[at - 1].startswith("   warnings heeded (commands considered, flagged, not issued): 2; ")
    assert out[at] == (f"   then the pilot, in drive mode through the bindings: run nav2:dock_robot ({dock}): cyclic, "
                       "2 moves when outcomes are favourable")
    assert re.fullmatch(r'     sent: send_goal /dock_robot goal [0-9a-f]{8}(-[0-9a-f]{4}){3}-[0-9a-f]{12} '
                        r'\{"dock_id": "home_dock", "use_dock_id": true\}: accepted', out[at + 1]), out[at + 1]
    assert out[at + 2:] == ["     robot: nav2:dock_robot.start, nav2:dock_robot.success.docked",
                            "   pilot: reached; 1 command sent, 0 denied; violations: 0", "",
                            "== the runs side by side",
                            "   run   commands  moves  retries  violations  denied",
                            "   nav2         5     12        1           0       -"]
    # Live (real time; here as fast as the chain goes): the same pilot part, after the run's summary.
    assert main(["demo", "nav2", "--live", "--speed", "0", "--linger", "0"]) == 0
    live = capsys.readouterr().out.splitlines()
    pilot = next(n for n, line in enumerate(live) if line.startswith("   then the pilot"))
    assert live[pilot - 1].startswith("   warnings heeded") and live[pilot] == out[at]
    assert live[pilot + 2:pilot + 4] == out[at + 2:at + 4]  # robot: ..., pilot: reached ...
    assert main(["demo", "nav2", "--core"]) == 0
    assert capsys.readouterr().out.splitlines()[-5] == (f"   (the pilot's goals, {dock}, need the chain of a bound "
                                                        "system: not played here)")


def test_a_bad_pilot_goals_file_stops_the_demo_before_the_run(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    run = (NAV2 / "missions" / "nav2_run.toml").read_text().replace('"../nav2.toml"', f'"{NAV2 / "nav2.toml"}"')
    (tmp_path / "run.toml").write_text(run.replace('pilot = "dock.toml"', 'pilot = "nodock.toml"'))
    assert main(["demo", str(tmp_path / "run.toml")]) == 1
    assert capsys.readouterr() == ("", f"{tmp_path / 'nodock.toml'}: error: cannot read file: No such file or "
                                       "directory\n")
    (tmp_path / "nodock.toml").write_text('[[goals]]\nrun = "nav2:dock_robt"\n')
    assert main(["demo", str(tmp_path / "run.toml")]) == 1
    assert capsys.readouterr() == ("", f"{tmp_path / 'nodock.toml'}:2:13: error: unknown skill 'dock_robt' of 'nav2' "
                                       "(candidates: dock_robot, undock_robot)\n")


def test_skinet_run_takes_the_robot_s_keys_for_its_pilot_and_the_bridge_it_prints(
        capsys: pytest.CaptureFixture[str]) -> None:
    """``skinet run ... --rmw-zenoh --domain 3``: its embedded pilot gets those keys (start_pilot's style, as the pilot
    process above), and the bridge command it prints reads them."""
    assert main(["run", str(NAV2 / "nav2.toml"), "--once", "--rmw-zenoh", "--domain", "3", "--no-properties"]) == 0
    lines = capsys.readouterr().err.splitlines()
    bridge = next(line for line in lines if "services.bridge_ros2" in line)
    assert re.fullmatch(rf"  python -m services.bridge_ros2 {re.escape(str(NAV2 / 'nav2.toml'))} --rmw-zenoh "
                        r"--domain 3 -e tcp/127\.0\.0\.1:\d+   \(the robot's side\)", bridge), bridge
