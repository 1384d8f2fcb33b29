"""The pilot (docs/semantics.md §8, *The pilot*; issue 24) on the paper's robot through a real router: simulated
managers speaking the real protocol, the bridge, the monitor, a predictor and the pilot on their own
sessions; the skills' outcomes come from :class:`~services.simulator.world.World`."""

from __future__ import annotations

import dataclasses
import random
import re
import threading
import time
from collections.abc import Callable

import pytest
import zenoh

from services.bridge_ros2 import Bridge, start_bridge
from services.common.zenoh_config import undeclare
from services.monitor import Monitor
from services.pilot import ActError
from services.predictor.service import start_predictor
from services.simulator.world import World
from skinet.pilot.run import Outcomes
from skinet.ros.derive import SkillView
from skinet.ros.keys import KeyStyle
from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.messages import PilotCommand, PilotGoalReply, PilotGoalRequest, Verdicts
from tests.event_watch import Messages
from tests.services.test_monitor import wait_until
from tests.services.pilot_robot import WALK, Gui, Robot, ask_goal, goal


# `skinet plan skillsets/spot_arm.toml "reach manipulator:RD" "run spot:go_to_waypoint"`, outcomes favourable.
MISSION = ["manipulator:arm_ready.start", "spot:init_power.start", "spot:stand_up.start",
           "manipulator:arm_RD_to_HP.start", "spot:go_to_waypoint.start"]
ENDS = ["ready", "powered_on", "standing", "at_home", "arrived"]


def drive_until_running(robot: Robot, skill: str) -> PilotGoalReply:
    """A driven goal to walk to the waypoint, once the pilot awaits the outcome of ``spot:skill`` (which the
    test's implementations hold)."""
    reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive"))
    robot.statuses.first(lambda s: s.reason == f"the outcome of spot:{skill}")
    return reply


def test_drive_reaches_a_mission_with_exactly_the_planned_commands(robot: Robot) -> None:
    impl = World(robot.sim)
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
    impl = World(robot.sim)
    gui = Gui(robot.observer, robot)
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK))
        assert (reply.accepted, reply.answer, reply.moves) == (True, "cyclic", 6)
        assert [(s.number, s.skillset, s.action, s.expect) for s in reply.steps[:2]] == [
            ("1", "spot", "init_power.start", None), ("2", "spot", "wait", "init_power.success.powered_on")]
        first = robot.statuses.first(lambda s: s.state == "guiding" and s.next is not None)
        assert (first.next.skillset, first.next.transition, first.next.inputs, first.mode) == (
            "spot", "init_power.start", {}, "guide")
        assert (first.answer, first.moves_left, first.goals) == ("cyclic", 6, ["run spot:go_to_waypoint"])
        gui.start("spot", "init_power")  # the operator follows the guide
        after = robot.statuses.first(lambda s: s.next is not None and s.next.transition == "stand_up.start")
        assert (after.state, after.moves_left) == ("guiding", 4)
        gui.start("spot", "stand_up")
        walk = robot.statuses.first(lambda s: s.next is not None and s.next.transition == "go_to_waypoint.start")
        assert walk.next.inputs == WALK["go_to_waypoint"]
        gui.start("spot", "go_to_waypoint", WALK["go_to_waypoint"])
        done = robot.statuses.state("reached", reply.goal_id)
        assert (robot.actuator.sent, done.commands, done.denied) == ([], 0, 0)
    finally:
        gui.close()
        impl.close()


def test_the_operators_interrupt_of_the_pilots_skill_is_reported_counted_and_not_restarted_unasked(
        robot: Robot) -> None:
    """Spot is standing up (held) when the operator interrupts it: the pilot says so, counts it against
    the retries and waits for `resume`; then it plans again from there and stands it up again."""
    impl = World(robot.sim, holding=[("spot", "stand_up")])
    gui = Gui(robot.observer, robot)
    try:
        reply = drive_until_running(robot, "stand_up")  # the pilot saw it start
        gui.interrupt("spot", "stand_up")
        # The status about the interrupt: a pause before it (the prediction of step 2 pending, on a busy machine)
        # is not it.
        held = robot.statuses.first(lambda s: s.goal_id == reply.goal_id and "interrupted by the operator" in s.reason,
                                    what="about the operator's interrupt")
        assert (held.state, held.reason) == (
            "paused", "spot:stand_up interrupted by the operator (1 of 3 tries): resume to go on")
        assert (held.retries, held.commands, held.notes) == (
            {"spot:stand_up": 1}, 2, ["spot:stand_up interrupted by the operator"])
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="resume")).accepted
        robot.statuses.first(lambda s: s.commands == 3, what="a third command")
        impl.release("spot", "stand_up")
        done = robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.start",
                                       "spot:go_to_waypoint.start"]
        assert (done.commands, done.denied, done.retries) == (4, 0, {"spot:stand_up": 1})
    finally:
        gui.close()
        impl.close()


def test_a_failed_skill_is_retried(robot: Robot) -> None:
    impl = World(robot.sim, script={("spot", "stand_up"): ["fell"]})
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive"))
        done = robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.start",
                                       "spot:go_to_waypoint.start"]
        assert (done.retries, done.commands) == ({"spot:stand_up": 1}, 4)
    finally:
        impl.close()


def test_max_retries_failures_of_one_skill_end_the_goal_with_skill_and_mode(robot: Robot) -> None:
    impl = World(robot.sim, script={("spot", "stand_up"): ["fell", "fell"]})
    try:
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive", max_retries=2))
        done = robot.statuses.state("failed", reply.goal_id)
        assert done.reason == "spot:stand_up failed 2 times (last: fell)"
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.start"]
        assert (done.retries, done.next) == ({"spot:stand_up": 2}, None)
    finally:
        impl.close()


@pytest.fixture
def quick(robots: Callable[..., Robot]) -> Robot:
    """The robot with a monitor that calls a skillset lost after 0.5 s of silence."""
    return robots(lost_after=0.5)


def test_a_skillset_not_live_pauses_the_pilot_until_it_is_live_again(quick: Robot, client_factory) -> None:
    robot = quick
    impl = World(robot.sim, holding=[("spot", "init_power")])
    try:
        reply = drive_until_running(robot, "init_power")
        robot.bridge.close()  # the robot goes silent
        paused = robot.statuses.first(lambda s: s.state == "paused" and " is lost: " in s.reason, what="lost")
        assert paused.reason.startswith(("spot is lost: the liveliness token of 'bridge_ros2/",
                                         "manipulator is lost: the liveliness token of 'bridge_ros2/")), paused.reason
        impl.release("spot", "init_power")  # spot powers on meanwhile: nobody sees it
        time.sleep(0.3)
        assert robot.actuator.sent == ["spot:init_power.start"]  # nothing from a state it cannot vouch for
        robot.bridge = start_bridge(client_factory(), robot.system, robot.typemap)  # heard again: resync
        done = robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:go_to_waypoint.start"]
        assert (done.commands, done.denied) == (3, 0)
    finally:
        impl.close()


def test_a_pending_prediction_pauses_the_pilot_until_it_comes(robot: Robot, client_factory) -> None:
    impl = World(robot.sim, holding=[("spot", "init_power")])
    try:
        reply = drive_until_running(robot, "init_power")
        robot.predictor.close()
        impl.release("spot", "init_power")
        paused = robot.statuses.first(lambda s: s.state == "paused" and s.commands == 1, what="paused")
        assert paused.reason == f"the prediction of step {paused.state_seq} is pending"
        assert (paused.next.skillset, paused.next.transition) == ("spot", "stand_up.start")  # what it would send
        time.sleep(0.3)
        assert robot.actuator.sent == ["spot:init_power.start"]
        robot.predictor = start_predictor(client_factory(), "pilot-test-2", workers=1)
        robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:go_to_waypoint.start"]
    finally:
        impl.close()


def test_a_model_divergence_pauses_the_pilot_until_resumed(robot: Robot) -> None:
    """The robot stands up with no skill (a model divergence): the pilot stops until the operator resumes,
    whatever steps the model explains come after it (here the operator makes it sit down), then goes on from
    the marking the monitor holds then."""
    impl = World(robot.sim, holding=[("spot", "init_power")])
    gui = Gui(robot.observer, robot)
    try:
        reply = drive_until_running(robot, "init_power")
        node = robot.sim.nodes["spot"]
        with node.lock:
            node.manager.resources["posture"] = "Standing"
        impl.release("spot", "init_power")  # its status shows the posture the model cannot explain
        paused = robot.statuses.first(lambda s: s.state == "paused" and "divergence" in s.reason, what="diverged")
        assert paused.reason.startswith(f"model divergence at step {paused.state_seq} (spot:"), paused.reason
        assert paused.reason.endswith("; resume to go on from the state the monitor adopted")
        gui.start("spot", "sit_down")  # two steps the model explains: the start and its success
        later = robot.statuses.first(lambda s: s.state_seq >= paused.state_seq + 2, what="sat down")
        assert (later.state, later.reason) == ("paused", paused.reason)  # later steps do not clear it
        time.sleep(0.3)
        assert robot.actuator.sent == ["spot:init_power.start"]
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="resume")).accepted
        robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:go_to_waypoint.start"]
    finally:
        gui.close()
        impl.close()


def test_a_manager_that_does_not_react_ends_the_goal(client_factory, spot_arm) -> None:
    robot = Robot(client_factory, *spot_arm, response_timeout=1.0)
    try:
        undeclare(*robot.sim._subscribers)  # the managers no longer hear requests; the bridge still hears them
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive"))
        failed = robot.statuses.state("failed", reply.goal_id)
        assert failed.reason == "no response from /spot/spot_skillset_manager within 1 s to spot:init_power.start"
        assert (robot.actuator.sent, failed.commands) == (["spot:init_power.start"], 1)
        assert robot.pilot.status.state == "failed"  # and the service lives: it takes the next goal
        assert ask_goal(robot.observer, goal("reach spot:PowerOff")).accepted
    finally:
        robot.close()


def test_bad_requests_get_a_clear_reason_and_never_a_command(robot: Robot) -> None:
    ask = lambda request: ask_goal(robot.observer, request)  # noqa: E731
    bad_goal = ask(goal("run spot:go_to_waypont", inputs=WALK, mode="drive"))
    assert (bad_goal.accepted, bad_goal.goal_id) == (False, 0)
    assert bad_goal.reason == "<goal>:1:10: error: unknown skill 'go_to_waypont' of 'spot' (candidates: go_to_waypoint)"
    mission = ask(PilotGoalRequest(system="spot_arm", mission='[[goals]]\nreach = "manipulator:RD"\n\n[[goals]]\n'
                                                              'reach = "spot:Standng"\n', mission_name="m.toml"))
    assert mission.reason.startswith("m.toml:5:10: error: "), mission.reason
    assert ask(b"\x93garbage").reason.startswith("malformed goal request: ")
    assert ask(None).reason == "empty goal request: send a PilotGoalRequest (msgpack)"
    assert ask_goal(robot.observer, goal("reach spot:Standing"), client="*").reason == (
        "key 'skinet/spot_arm/pilot/goal/*': the client chunk must be a name (skinet/spot_arm/pilot/goal/<client>)")
    assert ask(goal("reach spot:Standing", system="other")).reason == \
        "unknown system 'other': this pilot serves 'spot_arm'"
    unsafe = ask(goal("reach spot:Busy and manipulator:Busy", mode="drive"))
    assert unsafe.reason.startswith("goal 'reach spot:Busy and manipulator:Busy' has no plan from the live state: "
                                    "none: "), unsafe.reason
    assert ask(goal()).reason.startswith("no goals: ")
    assert ask(goal(*["reach spot:Standing"] * 33)).reason == "33 goals: a mission has at most 32"
    assert ask(PilotGoalRequest(system="spot_arm", op="pause")).reason == "no goal is being followed: nothing to pause"
    assert robot.pilot.status.state == "idle"
    # One goal at a time, unless the new one says replace.
    first = ask(goal("reach spot:Standing"))
    assert (first.accepted, first.goal_id) == (True, 1)
    busy = ask(goal("reach manipulator:RD"))
    assert (busy.accepted, busy.reason) == (False, "goal 1 of operator1 is being followed (guiding): cancel it "
                                                   "(--cancel), or send the new goal with --replace (the dashboard: "
                                                   "'replace the goal that runs')")
    second = ask(goal("reach manipulator:RD", replace=True))
    assert (second.accepted, second.goal_id) == (True, 2)
    assert robot.statuses.first(lambda s: s.goal_id == 1 and s.state == "cancelled").reason == \
        "replaced by goal 2 of operator1"
    guiding = robot.statuses.first(lambda s: s.goal_id == 2 and s.state == "guiding")
    assert (guiding.next.skillset, guiding.next.transition, guiding.client) == ("manipulator", "arm_ready.start",
                                                                              "operator1")
    assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel"), client="operator2").accepted
    cancelled = robot.statuses.first(lambda s: s.goal_id == 2 and s.state == "cancelled")
    assert cancelled.reason == "cancelled by operator2"
    assert robot.actuator.sent == []


def test_no_monitor_means_waiting_then_the_goal_goes_on(client_factory, spot_arm) -> None:
    robot = Robot(client_factory, *spot_arm, monitor=False)
    impl = World(robot.sim)
    try:
        robot.wait_pilot("waiting for monitor")
        assert robot.pilot.status.reason == ("no monitor of spot_arm is running (no token on "
                                             "skinet/spot_arm/alive/monitor/*)")
        reply = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive"))
        assert (reply.accepted, reply.answer, reply.steps) == (True, None, [])  # nothing to plan from yet
        time.sleep(0.3)
        assert (robot.pilot.status.state, robot.actuator.sent) == ("waiting for monitor", [])
        robot.start_monitor()
        robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
    finally:
        impl.close()
        robot.close()


def test_an_answer_to_the_pilots_get_older_than_a_publication_is_dropped(client_factory, spot_arm,
                                                                         monkeypatch) -> None:
    """The pilot asks a monitor that appears for its last state (``get``); here the answer leaves while
    the monitor is still syncing and comes after the state it published once synced, of the same step 0
    (what load did in the run where the goal stayed paused, "spot is syncing: the monitor started"):
    the pilot keeps the newer state and the goal goes on."""
    asked, sent = threading.Event(), threading.Event()
    answers: list = []
    latest, resync = Monitor._on_latest, Bridge._on_resync

    def answer_late(monitor: Monitor, name: str, key: str, query: zenoh.Query) -> None:
        if name != "state":
            return latest(monitor, name, key, query)
        answers.append(monitor.snapshot().state)  # what the monitor answers now...

        def send() -> None:  # ...is sent once the monitor has synced and published that
            wait_until(monitor.synced, 30, "the monitor synced")
            query.reply(key, encode(answers[-1]))
            query.drop()
            sent.set()
        threading.Thread(target=send, daemon=True).start()
        asked.set()

    def after_the_pilots_get(bridge: Bridge, query: zenoh.Query) -> None:
        asked.wait(10)  # the monitor is still syncing when the pilot's get comes
        resync(bridge, query)

    monkeypatch.setattr(Monitor, "_on_latest", answer_late)
    monkeypatch.setattr(Bridge, "_on_resync", after_the_pilots_get)
    robot = Robot(client_factory, *spot_arm, monitor=False)
    impl = World(robot.sim)
    try:
        robot.wait_pilot("waiting for monitor")
        robot.start_monitor()
        assert sent.wait(30), "the pilot did not ask the monitor for its state"
        assert [{n: s.state for n, s in a.sync.items()} for a in answers[:1]] == [
            {"spot": "syncing", "manipulator": "syncing"}]
        assert answers[0].seq == robot.monitor.snapshot().state.seq == 0  # the same step
        reply = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive"))
        robot.statuses.state("reached", reply.goal_id, timeout=30)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
    finally:
        impl.close()
        robot.close()


def test_a_manager_that_is_gone_pauses_the_pilot_with_no_command(client_factory, spot_arm) -> None:
    """rmw_zenoh keys: the managers' liveliness tokens say when they leave."""
    robot = Robot(client_factory, *spot_arm, style=KeyStyle(rmw_zenoh=True, domain=23))
    try:
        robot.sim.close()
        # a goal asked before the loss reached the pilot would be planned from the live state it still had (a
        # full run saw init_power.start sent so): the pilot's own state says spot is lost first
        wait_until(lambda: (st := robot.pilot._state) is not None and "spot" in st.sync
                   and st.sync["spot"].state == "lost", 30, "the pilot's live state shows spot lost")
        reply = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive"))
        paused = robot.statuses.first(lambda s: s.goal_id == reply.goal_id and s.state == "paused" and
                                     "manager left" in s.reason, what="its manager left")
        assert "spot is lost: its manager left (said 'bridge_ros2/" in paused.reason, paused.reason
        time.sleep(0.5)
        assert robot.actuator.sent == []
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel")).accepted
    finally:
        robot.close()


RACE_GOALS = ["reach manipulator:RD and spot:Standing", "reach manipulator:HP and spot:Sitting and spot:PowerOff",
              "run spot:go_to_waypoint", "reach spot:Sitting and manipulator:RD"]


@pytest.mark.parametrize("seed", [1, 2])
def test_outcomes_at_random_moments_around_commands_never_lead_to_a_violation(robot: Robot, seed: int) -> None:
    """docs/semantics.md §8, *Races*: both components' skills end at random moments (0 to 30 ms after they start,
    a quarter of them in a failure mode), so outcomes arrive before, during and after the pilot's
    commands to the other component; 12 goals per seed, every one reached, no command denied, no
    property ever violated."""
    verdicts = Messages(robot.observer, keys.verdicts("spot_arm"), Verdicts)
    impl = World(robot.sim, Outcomes(robot.system, failure_rate=0.25, seed=seed), 0.03, rng=random.Random(seed))
    try:
        commands = 0
        for n in range(12):
            reply = ask_goal(robot.observer, goal(RACE_GOALS[n % 4], inputs=WALK, mode="drive", max_retries=100))
            assert reply.accepted, reply.reason
            done = robot.statuses.first(lambda s: s.goal_id == reply.goal_id and s.state in ("reached", "failed"),
                                       timeout=60)
            assert (done.state, done.reason, done.denied) == ("reached", "", 0)
            commands += done.commands
        assert [(v.seq, p.name) for v in verdicts.items for p in v.properties if not p.holds] == []
        assert any(e.split(".")[1] == "failure" for e in impl.ended)  # failures did come
        assert len(robot.actuator.sent) == commands  # every command counted was sent, and only those
    finally:
        impl.close()


def test_switching_to_drive_and_pausing_by_the_operator(robot: Robot) -> None:
    impl = World(robot.sim)
    try:
        reply = ask_goal(robot.observer, goal("reach spot:Standing"))
        robot.statuses.first(lambda s: s.state == "guiding" and s.next is not None)
        pause = ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="pause"), client="operator2")
        assert (pause.accepted, pause.goal_id) == (True, reply.goal_id)
        assert robot.statuses.first(lambda s: s.state == "paused").reason == "paused by operator2"
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="mode", mode="drive")).accepted
        time.sleep(0.3)
        assert (robot.pilot.status.state, robot.pilot.status.mode, robot.actuator.sent) == ("paused", "drive", [])
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="resume")).accepted
        robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
    finally:
        impl.close()


def test_the_actuator_interrupts_with_the_running_id_its_manager_shows(robot: Robot) -> None:
    """The running id comes from the manager's own status, whoever started the skill."""
    gui = Gui(robot.observer, robot)
    actuator = robot.actuator.inner.actuators["manager"]
    try:
        gui.start("spot", "init_power")
        wait_until(lambda: robot.sim.skill_status("spot", "init_power") == (True, "gui-1"), 30, "init_power runs")
        interrupt = PilotCommand(skillset="spot", transition="init_power.interrupt")
        sent = actuator.send(interrupt)
        assert sent == "init_power.interrupt (running id 'gui-1') on spot/spot_skillset_manager/spot_skillset/skill/" \
                       "init_power/interrupt"
        wait_until(lambda: not robot.sim.skill_status("spot", "init_power")[0], 30, "init_power interrupted")
        with pytest.raises(ActError, match=r"^spot:init_power is not running according to /spot/spot_skillset_"
                                           r"manager's last status$"):
            wait_until(lambda: actuator._ids["spot"]["init_power"].state == 0, 30, "the status seen")
            actuator.send(interrupt)
        with pytest.raises(ActError, match=r"^cannot encode spot:go_to_waypoint.start: spot:go_to_waypoint has no "
                                           r"input 'goal' \(inputs: target\)$"):
            actuator.send(PilotCommand(skillset="spot", transition="go_to_waypoint.start", inputs={"goal": 1.0}))
        assert actuator.send(PilotCommand(skillset="spot", transition="init_power.start")) == \
            "init_power.start (id 'p1-1') on spot/spot_skillset_manager/spot_skillset/skill/init_power/request"
        wait_until(lambda: robot.sim.skill_status("spot", "init_power") == (True, "p1-1"), 30, "started by the pilot")
    finally:
        gui.close()


def test_an_interrupt_asks_again_when_the_last_status_it_saw_predates_the_start(robot: Robot) -> None:
    """The last status the actuator saw shows the skill ready (it came before the start's, as a run of session
    19's saw): the actuator asks the manager and interrupts the execution its answer shows running."""
    gui = Gui(robot.observer, robot)
    actuator = robot.actuator.inner.actuators["manager"]
    try:
        gui.start("spot", "init_power")
        wait_until(lambda: actuator._ids.get("spot", {}).get("init_power") == SkillView(1, "gui-1"), 30,
                   "the actuator sees init_power run")
        with actuator._lock:  # the status before the start, as if the start's were still on its way
            actuator._ids["spot"] = {**actuator._ids["spot"], "init_power": SkillView(0, "")}
        sent = actuator.send(PilotCommand(skillset="spot", transition="init_power.interrupt"))
        assert sent == "init_power.interrupt (running id 'gui-1') on spot/spot_skillset_manager/spot_skillset/skill/" \
                       "init_power/interrupt"
        wait_until(lambda: not robot.sim.skill_status("spot", "init_power")[0], 30, "init_power interrupted")
    finally:
        gui.close()


def test_a_command_the_check_denies_is_a_defect_never_sent(client_factory, spot_arm) -> None:
    """A pilot whose model lacks safety_guard (the monitor's has it) plans to walk with the arm ready:
    the monitor's strict check denies the walk, and the pilot counts the defect and sends nothing."""
    system, typemap = spot_arm
    weaker = dataclasses.replace(system, properties=tuple(p for p in system.properties if p.name != "safety_guard"))
    robot = Robot(client_factory, system, typemap, pilot_system=weaker)
    impl = World(robot.sim)
    gui = Gui(robot.observer, robot)
    try:
        gui.start("manipulator", "arm_ready")
        robot.statuses.first(lambda s: s.state == "idle" and s.state_seq == 2, what="the arm ready")
        reply = ask_goal(robot.observer, goal("run spot:go_to_waypoint", inputs=WALK, mode="drive"))
        assert reply.accepted, reply.reason
        paused = robot.statuses.first(lambda s: s.denied == 1, what="a denied command")
        assert (paused.state, paused.next.transition) == ("paused", "go_to_waypoint.start")
        assert paused.reason.startswith(f"the check answered deny for spot:go_to_waypoint.start at step "
                                        f"{paused.state_seq}: safety_guard (explicit): "), paused.reason
        time.sleep(0.5)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel")).accepted
        assert robot.statuses.state("cancelled", reply.goal_id).denied == 1  # asked once at that step
    finally:
        gui.close()
        impl.close()
        robot.close()


def test_drive_through_rmw_zenoh_keys(client_factory, spot_arm) -> None:
    """The pilot's requests on rmw_zenoh keys, with their attachments, reach the managers."""
    robot = Robot(client_factory, *spot_arm, style=KeyStyle(rmw_zenoh=True, domain=31))
    impl = World(robot.sim)
    try:
        reply = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive"))
        robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
        assert robot.sim.skill_status("spot", "stand_up") == (False, "p1-2")  # the pilot's own request ids
    finally:
        impl.close()
        robot.close()


def test_a_start_the_manager_refuses_is_asked_again_then_ends_the_goal(robot: Robot) -> None:
    """A faulty manager refuses init_power (its preconditions, it says, are false): nothing changes on the
    robot, so the pilot learns it from the manager's response, asks again, and gives up after max_retries."""
    manager = robot.sim.nodes["spot"].manager
    skill = manager.skillset.skill("init_power")

    def refuse(name: str, id_: str, input_: object = None) -> list:
        manager.skills[name].id = id_  # as the generated manager does: the id kept, the start refused
        return [manager._response(skill, "PRECONDITION_FAILURE", preconditions={p.name: False for p in skill.preconditions}),
                manager.status()]

    manager.skill_request = refuse
    reply = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive", max_retries=2))
    refused = robot.statuses.first(lambda s: s.state == "paused" and "refused" in s.reason, what="refused once")
    assert refused.reason == ("/spot/spot_skillset_manager refused spot:init_power.start: PRECONDITION_FAILURE "
                              f"({', '.join(p.name for p in skill.preconditions)} false)")
    failed = robot.statuses.state("failed", reply.goal_id)
    assert failed.reason == refused.reason + " (2 times)"
    assert (robot.actuator.sent, failed.commands) == ([], 2)  # sent, refused: the recording keeps what went through


@pytest.mark.parametrize("budget", [1e308, 86400.5, 0.0, float("nan")])
def test_a_planning_budget_past_one_day_is_refused(budget: float) -> None:
    """Past one day a planning deadline would mean "never" (issue 30); refused before any session is used."""
    from pathlib import Path

    from services.pilot.service import Pilot
    from skinet.system.load import load_system

    system, _ = load_system(Path(__file__).resolve().parents[2] / "skillsets" / "spot_arm.toml")
    with pytest.raises(ValueError) as info:
        Pilot(None, system, budget=budget)  # type: ignore[arg-type]
    assert str(info.value) == f"planning budget {budget:g} s is not from 0 to 86400 s (one day)"


def test_past_its_memory_limit_the_pilot_answers_unknown_and_takes_no_goal(robots) -> None:
    """The limit is the whole process's resident memory (a pilot inside ``skinet run`` gets the run's
    ``--memory-limit``): past it no plan is promised, and the goal is refused with why, never followed."""
    robot = robots(memory_limit=1 << 20)  # any process is past 1 MiB
    reply = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive"))
    assert (reply.accepted, reply.goal_id) == (False, 0)
    assert reply.reason == ("goal 'reach spot:Standing' has no plan from the live state: unknown: the memory limit "
                            "(1 MiB, the whole process) was reached before the fixpoints ended (0 markings, "
                            "exploration cut by the memory)"), reply.reason
    assert (robot.pilot.status.state, robot.actuator.sent) == ("idle", [])
    from services.pilot.service import Pilot

    with pytest.raises(ValueError) as info:
        Pilot(None, robot.system, memory_limit=0)  # type: ignore[arg-type]
    assert str(info.value) == "memory limit 0 bytes is not positive"


def test_a_huge_mission_is_refused_by_its_goal_count_and_a_cancel_right_after_is_answered(robot: Robot) -> None:
    """5 000 goals (160 KB): counted before any is parsed (parsing them took minutes: every goal's
    position was searched from the top of the text), and parsed off the queryable's thread."""
    assert ask_goal(robot.observer, goal("reach spot:Standing")).accepted
    robot.statuses.state("guiding", 1)
    mission = '[[goals]]\nreach = "spot:Standing"\n' * 5000
    assert 150_000 < len(mission) < 256 << 10
    huge: list = []
    sender = threading.Thread(target=lambda: huge.append(ask_goal(
        robot.observer, PilotGoalRequest(system="spot_arm", mission=mission, mission_name="m.toml", replace=True))))
    sender.start()
    cancel = ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel"), client="operator2")
    sender.join(15.0)
    assert cancel.accepted
    assert robot.statuses.state("cancelled", 1).reason == "cancelled by operator2"
    assert [(r.accepted, r.reason) for r in huge] == [(False, "5000 goals: a mission has at most 32")]


def test_a_mission_past_the_limit_is_refused_at_the_first_goal_too_many() -> None:
    from skinet.errors import SourceError
    from skinet.system.load import load_system
    from skinet.plan import parse_goals

    system, typemap = load_system("skillsets/spot_arm.toml")
    with pytest.raises(SourceError) as refused:
        parse_goals('[[goals]]\nreach = "spot:Standing"\n' * 4, system, "m.toml", typemap, max_goals=3)
    assert str(refused.value) == "m.toml:7:1: error: 4 goals: a mission has at most 3"
    assert len(parse_goals('[[goals]]\nreach = "spot:Standing"\n' * 3, system, "m.toml", typemap, 3)) == 3


def test_from_a_violation_the_goal_is_refused_naming_the_way_back_unless_it_asks_to_recover(robot: Robot) -> None:
    """Issue 30: from a violated marking the answer names every violated property and the commands that lead
    back into Safe; with `recover`, the pilot sends the first of them, then plans again from Safe."""
    impl = World(robot.sim, holding=[("spot", "teleop"), ("manipulator", "arm_joystick")])
    gui = Gui(robot.observer, robot)
    try:
        for skillset, skill in (("spot", "init_power"), ("spot", "stand_up"), ("manipulator", "arm_ready")):
            gui.start(skillset, skill)
            wait_until(lambda: any(e.startswith(f"{skillset}:{skill}.success") for e in impl.ended), 30,
                       f"{skillset}:{skill} ended")
        for skillset, skill in (("manipulator", "arm_joystick"), ("spot", "teleop")):  # both held: both Busy
            gui.start(skillset, skill)
            wait_until(lambda: skill in robot.monitor.snapshot().state.skillsets[skillset].running, 30,
                       f"{skillset}:{skill} running")
        robot.wait_pilot_step()
        refused = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive"))
        assert not refused.accepted
        assert refused.reason.startswith("goal 'reach spot:Standing' has no plan from the live state: none: the robot "
                                         "is in a marking forced for action_guard")
        assert refused.reason.endswith("recover first with one of spot:teleop.interrupt, "
                                       "manipulator:arm_joystick.interrupt (each leads back into Safe whatever its "
                                       "outcome), then plan again"), refused.reason
        reply = ask_goal(robot.observer, goal("reach spot:Standing", mode="drive", recover=True))
        assert (reply.accepted, reply.answer) == (True, "none")
        done = robot.statuses.state("reached", reply.goal_id)
        assert robot.actuator.sent == ["spot:teleop.interrupt"]
        assert done.commands == 1 and done.denied == 0
        assert done.notes[0].startswith("recovering first with spot:teleop.interrupt (back into Safe whatever its "
                                        "outcome), then planning again: the robot is in a marking forced for "
                                        "action_guard"), done.notes
    finally:
        gui.close()
        impl.close()


def test_a_cancel_leaves_the_pilots_skill_running_unless_it_asks_to_interrupt_it(robot: Robot) -> None:
    """docs/pilot.md, *Cancelling*: a plain cancel sends nothing more, and spot:stand_up runs on."""
    impl = World(robot.sim, holding=[("spot", "stand_up")])
    try:
        reply = drive_until_running(robot, "stand_up")  # the pilot saw it start
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel")).accepted
        done = robot.statuses.state("cancelled", reply.goal_id)
        assert (done.reason, done.interrupts, done.next) == ("cancelled by operator1", {}, None)
        time.sleep(0.5)  # nothing more is sent
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
        assert robot.sim.skill_status("spot", "stand_up")[0]
        late = ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel", interrupt=True))
        assert (late.accepted, late.reason) == (False, "no goal is being followed: nothing to cancel")
    finally:
        impl.close()


def test_a_cancel_with_interrupt_interrupts_the_skill_the_pilot_started_through_the_check(robot: Robot) -> None:
    """The pilot's stand_up runs (held) when the goal is cancelled with interrupt: the pilot checks its
    interrupt, sends it, and the status says so at each change."""
    impl = World(robot.sim, holding=[("spot", "stand_up")])
    try:
        reply = drive_until_running(robot, "stand_up")
        cancel = ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel", interrupt=True))
        assert (cancel.accepted, cancel.goal_id) == (True, reply.goal_id)
        done = robot.statuses.first(lambda s: s.interrupts.get("spot:stand_up") == "interrupted",
                                    what="stand_up interrupted")
        assert (done.state, done.next, done.commands) == ("cancelled", None, 3)
        assert done.reason == "cancelled by operator1; spot:stand_up interrupted"
        assert done.notes[-2:] == ["interrupt of spot:stand_up sent: the check allowed it at step "
                                   f"{done.state_seq - 1}", "spot:stand_up interrupted"]
        # A step's prediction on its way is said, or not, as the predictor is quick or not (docs/semantics.md §7).
        shown = [(s.reason, s.next and s.next.transition, s.interrupts) for s in robot.statuses.items
                 if s.goal_id == reply.goal_id and s.state == "cancelled" and ": waiting for the prediction of step "
                 not in s.reason]
        assert shown == [
            ("cancelled by operator1; interrupting spot:stand_up, which the pilot started", "stand_up.interrupt",
             {"spot:stand_up": "pending"}),
            ("cancelled by operator1; interrupting spot:stand_up, which the pilot started: sent, waiting for its "
             "effect", "stand_up.interrupt", {"spot:stand_up": "sent"}),
            ("cancelled by operator1; spot:stand_up interrupted", None, {"spot:stand_up": "interrupted"})], shown
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "spot:stand_up.interrupt"]
        assert not robot.sim.skill_status("spot", "stand_up")[0]
    finally:
        impl.close()


def test_a_cancel_with_interrupt_never_interrupts_a_skill_the_operator_started(robot: Robot) -> None:
    """Guide mode: the operator started stand_up as the pilot showed; the cancel interrupts nothing."""
    impl = World(robot.sim, holding=[("spot", "stand_up")])
    gui = Gui(robot.observer, robot)
    try:
        reply = ask_goal(robot.observer, goal("reach spot:Standing"))
        robot.statuses.first(lambda s: s.next is not None and s.next.transition == "init_power.start")
        gui.start("spot", "init_power")
        robot.statuses.first(lambda s: s.next is not None and s.next.transition == "stand_up.start")
        gui.start("spot", "stand_up")
        robot.statuses.first(lambda s: s.reason == "the outcome of spot:stand_up")
        assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel", interrupt=True)).accepted
        done = robot.statuses.state("cancelled", reply.goal_id)
        assert (done.reason, done.interrupts, done.next) == (
            "cancelled by operator1; no skill the pilot started runs: nothing to interrupt", {}, None)
        time.sleep(0.5)  # nothing is sent
        assert robot.actuator.sent == [] and robot.sim.skill_status("spot", "stand_up")[0]
    finally:
        gui.close()
        impl.close()


def cancel_while_silent(robot: Robot) -> PilotGoalReply:
    """The pilot's stand_up runs, the robot goes silent (spot lost), and the goal is cancelled with interrupt."""
    reply = drive_until_running(robot, "stand_up")
    robot.bridge.close()
    robot.statuses.first(lambda s: s.state == "paused" and "spot is lost: " in s.reason, what="lost")
    assert ask_goal(robot.observer, PilotGoalRequest(system="spot_arm", op="cancel", interrupt=True)).accepted
    return reply


def test_an_interrupt_waits_for_a_live_skillset_and_gives_up_a_run_it_cannot_vouch_for(quick: Robot,
                                                                                       client_factory) -> None:
    """The robot goes silent just as the goal is cancelled with interrupt: the interrupt waits (spot is not live),
    stand_up ends unseen meanwhile, and once the bridge is back the monitor takes spot's state anew: the pilot
    cannot tell that a skill running then is its own run, so it sends nothing and says so."""
    robot = quick
    impl = World(robot.sim, holding=[("spot", "stand_up")])
    try:
        cancel_while_silent(robot)
        waiting = robot.statuses.first(lambda s: s.state == "cancelled", what="cancelled")
        assert waiting.reason.startswith("cancelled by operator1; interrupting spot:stand_up, which the pilot "
                                         "started: spot is lost: "), waiting.reason
        assert (waiting.interrupts, waiting.next.transition) == ({"spot:stand_up": "pending"}, "stand_up.interrupt")
        impl.release("spot", "stand_up")  # it stands up meanwhile: nobody sees it
        # Ended before a bridge listens again (a busy machine once ended it after: the bridge saw the outcome).
        wait_until(impl.idle, 10, "stand_up ended while the robot is silent")
        robot.bridge = start_bridge(client_factory(), robot.system, robot.typemap)  # heard again: resync
        done = robot.statuses.first(lambda s: s.interrupts.get("spot:stand_up") == "not interrupted",
                                    what="given up")
        assert done.reason == ("cancelled by operator1; spot:stand_up not interrupted: the pilot cannot tell that the "
                               "run is the one it started (spot's state was taken from its manager anew)")
        assert (done.next, robot.actuator.sent) == (None, ["spot:init_power.start", "spot:stand_up.start"])
    finally:
        impl.close()


def test_an_interrupt_that_cannot_be_sent_in_time_is_given_up_and_said(robots: Callable[..., Robot]) -> None:
    """docs/pilot.md, *Cancelling*: the robot is silent when the goal is cancelled with interrupt; past the
    pilot's interrupt wait (1 s here, 30 s by default) the interrupt is given up, with why, and never sent,
    although spot comes back and stand_up still runs."""
    robot = robots(lost_after=0.5, interrupt_wait=1.0)
    impl = World(robot.sim, holding=[("spot", "stand_up")])
    try:
        reply = cancel_while_silent(robot)
        done = robot.statuses.first(lambda s: s.interrupts.get("spot:stand_up") == "not interrupted",
                                    what="given up")
        assert re.fullmatch(r"cancelled by operator1; spot:stand_up not interrupted: not sent within 1 s of the "
                            r"cancel \(spot is lost: .+\)", done.reason), done.reason
        assert (done.goal_id, done.state, done.next) == (reply.goal_id, "cancelled", None)
        robot.bridge = start_bridge(robot.sessions(), robot.system, robot.typemap)  # heard again
        robot.wait_synced()
        time.sleep(0.5)  # nothing is sent now
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start"]
        assert robot.sim.skill_status("spot", "stand_up")[0]
    finally:
        impl.close()
