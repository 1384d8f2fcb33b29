"""Honest live state (docs/semantics.md §7; issue 25 items 1-4): the monitor never vouches for a marking it
does not know.

Real parts: simulated managers (the only stand-in, for the robot), the bridge as a process of
its own (so that it can be killed or frozen), the monitor and a predictor, all clients of a
loopback router.  The check is asked over Zenoh as any client asks it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from chains.chain import run_chain
from services.monitor import Monitor, start_monitor
from services.predictor.service import start_predictor
from services.simulator import Simulator
from skinet.system.load import load_system, load_typemap
from skinet.mission.scenario import Scenario, Step, StepRecord
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.convert import statuses
from skinet.wire.messages import CheckReply, CheckRequest, LiveState
from tests.services.conftest import LivelinessWatch, client_args
from tests.services.test_monitor import AG, PAPER_STEPS, SG, wait_until

REPO = Path(__file__).resolve().parents[2]
SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
ARM_AT_RD = [(s, t) for s, t, _, _ in PAPER_STEPS[:6]]  # spot standing, the arm at RD: the paper's warning 1
ARM_HOME = [("manipulator", "arm_RD_to_HP.start"), ("manipulator", "arm_RD_to_HP.success.at_home")]


def scenario(steps: list[tuple[str, str]], name: str = "live") -> Scenario:
    return Scenario(name, "spot_arm.toml", tuple(Step(float(i), s, t) for i, (s, t) in enumerate(steps)))


@dataclass
class Robot:
    """Simulated managers and a predictor in this process; the bridge as a process; monitors on demand."""

    system: System
    simulator: Simulator
    open_client: Callable[[], zenoh.Session]
    spawn: Callable[..., subprocess.Popen]
    router: str
    asker: zenoh.Session
    bridge: subprocess.Popen | None = None

    def start_bridge(self, instance: str) -> subprocess.Popen:
        watch = LivelinessWatch(self.asker, keys.alive("spot_arm", "bridge_ros2", instance))
        self.bridge = self.spawn("services.bridge_ros2", str(SYSTEM_FILE), "--instance", instance,
                                 *client_args(self.router))
        watch.wait(bool, 30)
        watch.close()
        return self.bridge

    def monitor(self, **options: object) -> Monitor:
        return start_monitor(self.open_client(), self.system, **options)

    def drive(self, steps: list[tuple[str, str]]) -> None:
        self.simulator.drive(scenario(steps), speed=0)

    def check(self, command: str, **fields: object) -> CheckReply:
        skillset, _, transition = command.partition(":")
        request = CheckRequest(skillset=skillset, transition=transition, **fields)  # type: ignore[arg-type]
        replies = [r for r in self.asker.get(keys.check("spot_arm", keys.LOCAL_CLIENT), payload=encode(request),
                                             timeout=5.0 + request.wait) if r.ok is not None]
        assert len(replies) == 1, replies
        return decode(replies[0].ok.payload.to_bytes(), CheckReply)


@pytest.fixture
def robot(client_factory, spawn, router, spot_arm) -> Iterator[Robot]:
    system, typemap = spot_arm
    simulator = Simulator(client_factory(), system, typemap)
    predictor = start_predictor(client_factory(), "live")
    r = Robot(system, simulator, client_factory, spawn, router, client_factory())
    try:
        yield r
    finally:
        if r.bridge is not None and r.bridge.poll() is None:
            r.bridge.send_signal(signal.SIGCONT)
        predictor.close()
        simulator.close()


def kinds(reply: CheckReply) -> list[tuple[str, str, str]]:
    return [(r.property, r.constraint, r.action) for r in reply.reasons]


def sees(monitor: Monitor, skillset: str, resource: str, state: str) -> Callable[[], bool]:
    return lambda: monitor.snapshot().state.skillsets[skillset].resources[resource] == state


def test_a_monitor_restarted_mid_run_answers_state_unknown_until_synced(robot: Robot) -> None:
    """Issue 25 item 1: a restarted monitor used to publish the initial marking and answer ``allow``
    to commands that violate a property now, until the next event came."""
    bridge = robot.start_bridge("b1")
    first = robot.monitor()
    robot.drive(ARM_AT_RD)
    wait_until(sees(first, "manipulator", "arm_status", "RD"), 10, "the first monitor following the robot")
    assert kinds(robot.check("spot:go_to_waypoint.start", wait=10)) == [(SG, "explicit", "warn")]
    token = keys.alive("spot_arm", "monitor", first.instance_id)
    watch = LivelinessWatch(robot.asker, token)
    first.close()
    first.session.close()
    watch.wait(lambda alive: token not in alive)
    watch.close()
    os.kill(bridge.pid, signal.SIGSTOP)  # frozen: nobody answers the new monitor's resync
    second = robot.monitor(resync_timeout=0.5)
    reply = robot.check("spot:go_to_waypoint.start")
    # It knows nothing yet: the marking it holds is the model's initial one (arm at home, where the
    # command violates nothing); the answer says so and is never a plain allow.
    assert (reply.ok, reply.decision, reply.state_stale) == (True, "warn", True)
    assert ("", "state_unknown", "warn") in kinds(reply) and (SG, "explicit", "warn") not in kinds(reply)
    assert "spot syncing since" in reply.state_reason and "manipulator syncing since" in reply.state_reason
    assert robot.check("spot:go_to_waypoint.start", policy="strict").decision == "deny"
    state = second.snapshot().state
    assert {n: s.state for n, s in state.sync.items()} == {"spot": "syncing", "manipulator": "syncing"}
    # A request that waits is answered once the monitor has synced, with the decision of the live marking.
    waited: list[CheckReply] = []
    asker = threading.Thread(target=lambda: waited.append(robot.check("spot:go_to_waypoint.start", wait=15)))
    asker.start()
    time.sleep(0.5)
    assert not waited, "answered before the state was synced"
    os.kill(bridge.pid, signal.SIGCONT)
    asker.join(20)
    assert waited and (waited[0].decision, waited[0].state_stale, waited[0].prediction_stale) == ("warn", False, False)
    assert kinds(waited[0]) == [(SG, "explicit", "warn")]
    assert sees(second, "manipulator", "arm_status", "RD")() and second.synced()
    assert robot.check("spot:sit_down.start", wait=10).decision == "allow"
    second.close()


def test_a_killed_bridge_turns_checks_state_unknown_within_the_bound_and_they_recover(robot: Robot) -> None:
    """Issue 25 item 2: with the bridge gone, the check went on answering from a frozen marking."""
    bridge = robot.start_bridge("b1")
    monitor = robot.monitor(check_rate_limit=0)  # asked every 20 ms below
    robot.drive(ARM_AT_RD)
    wait_until(sees(monitor, "manipulator", "arm_status", "RD"), 10, "the monitor following the robot")
    assert robot.check("spot:sit_down.start", wait=10).decision == "allow"
    bridge.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    while robot.check("spot:sit_down.start").decision == "allow":
        assert time.monotonic() - killed < monitor.lost_after, "still allowed past the bound"
        time.sleep(0.02)
    reply = robot.check("spot:sit_down.start")
    assert (reply.decision, kinds(reply)[-1:], reply.state_stale) == ("warn", [("", "state_unknown", "warn")], True)
    assert "spot lost since" in reply.state_reason and "the liveliness token of 'bridge_ros2/b1' is gone" \
        in reply.state_reason
    assert robot.check("spot:sit_down.start", policy="strict").decision == "deny"
    # The robot goes on without the bridge: the arm goes home.  The monitor cannot know.
    robot.drive(ARM_HOME)
    assert kinds(robot.check("spot:go_to_waypoint.start"))[0] == (SG, "explicit", "warn")
    robot.start_bridge("b2")  # the bridge comes back (a new run): resynced before live
    back = robot.check("spot:go_to_waypoint.start", wait=15)
    assert (back.decision, back.reasons, back.state_stale) == ("allow", [], False)
    assert sees(monitor, "manipulator", "arm_status", "HP")()
    assert {s.source for s in monitor.snapshot().state.sync.values()} == {"bridge_ros2/b2"}
    monitor.close()


def test_a_frozen_bridge_is_lost_after_the_bound_then_resynced(robot: Robot) -> None:
    """Its liveliness token stays for the lease (10 s): the silence of its heartbeats tells."""
    bridge = robot.start_bridge("b1")
    monitor = robot.monitor(lost_after=1.0)
    states: list[LiveState] = []
    sub = robot.asker.declare_subscriber(keys.state("spot_arm"), lambda s: states.append(
        decode(s.payload.to_bytes(), LiveState)))
    try:
        wait_until(monitor.synced, 10, "synced")
        os.kill(bridge.pid, signal.SIGSTOP)
        frozen = time.monotonic()
        wait_until(lambda: not monitor.synced(), 5, "lost")
        assert 0.9 < time.monotonic() - frozen < 1.0 + 0.6  # the bound, plus one heartbeat and one tick
        lost = monitor.snapshot().state.sync["spot"]
        assert lost.state == "lost" and lost.reason == \
            "nothing heard from 'bridge_ros2/b1' for 1 s (no heartbeat, no event)"
        os.kill(bridge.pid, signal.SIGCONT)
        wait_until(monitor.synced, 10, "live again")

        def changes() -> list[str]:
            seen = [s.sync["spot"].state for s in states]
            return [a for a, b in zip(seen, [None, *seen]) if a != b]

        wait_until(lambda: changes()[-1] == "live", 5, "the publication of it")
        assert changes()[-3:] == ["lost", "syncing", "live"]  # (its first states may precede the subscriber)
    finally:
        sub.undeclare()
        monitor.close()


def _mission(robot_clock: Callable[[], float], client_factory, spot_arm) -> list[tuple]:
    system, typemap = spot_arm
    session = client_factory()
    simulator = Simulator(session, system, typemap, clock=robot_clock)
    records = run_chain(system, typemap, scenario([(s, t) for s, t, _, _ in PAPER_STEPS]), predict=False,
                        session=session, simulator=simulator)
    simulator.close()
    return [(r.index, r.violations, r.divergence, sorted((f.property, f.constraint) for f in r.flagged),
             r.unsafe_count) for r in records]


def test_stamps_from_simulated_time_give_the_wall_clock_verdicts(client_factory, spot_arm) -> None:
    """Issue 25 item 3: events stamped more than 2 s before the monitor started were dropped as
    history, so a robot on simulated time (or with an unsynced clock) was not followed at all."""
    wall = _mission(time.time, client_factory, spot_arm)
    assert [(i, v) for i, v, *_ in wall if v] == [(10, [AG])]  # the paper's warning ignored
    start = time.monotonic()
    simulated = _mission(lambda: time.monotonic() - start, client_factory, spot_arm)  # from 1970-01-01
    future = _mission(lambda: time.time() + 10 * 365 * 86400, client_factory, spot_arm)
    assert simulated == wall and future == wall


def test_terminal_views_show_a_stale_state_first_in_colour() -> None:
    """``skinet watch`` and ``skinet run``: one banner line per skillset not live, red when lost, yellow
    when syncing (on a terminal), and a mark on the skillset's line."""
    from chains.embedded import RED, YELLOW, PLAIN, Observed, render, summary
    from skinet.wire.messages import PropertyVerdict, SkillsetSync, UnsafeReport, Verdicts

    system = load_system(SYSTEM_FILE)[0]
    state = LiveState(system="spot_arm", seq=3, stamp=0.0, skillsets=statuses(system, system.initial_marking()),
                      sync={"spot": SkillsetSync(state="lost", since=0.0, reason="its manager left"),
                            "manipulator": SkillsetSync(state="syncing", since=0.0, reason="waiting")})
    view = Observed(state, Verdicts(system="spot_arm", seq=3, stamp=0.0, properties=[
        PropertyVerdict(name=AG, holds=True)]), UnsafeReport(system="spot_arm", seq=3, stamp=0.0, unsafe=[],
                                                             prediction_stale=True), None)
    at = time.strftime("%H:%M:%S", time.localtime(0.0))
    lines = render(view, colour=True)
    assert lines[1:3] == [f"{RED}  STATE LOST: spot since {at}: its manager left{PLAIN}",
                          f"{YELLOW}  STATE SYNCING: manipulator since {at}: waiting{PLAIN}"]
    assert lines[4].endswith(f"running: -  [LOST since {at}]")
    assert render(view)[1] == f"  STATE LOST: spot since {at}: its manager left"
    assert summary(view).endswith(f" | STATE STALE: spot lost since {at}, manipulator syncing since {at}")
    live = state.model_copy(update={"sync": {n: SkillsetSync(state="live", since=0.0) for n in state.sync}})
    assert not [line for line in render(Observed(live, view.verdicts, view.unsafe, None)) if "STATE" in line]


STANDING = [("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
            ("spot", "stand_up.success.standing")]


def _ask(session: zenoh.Session, command: str) -> CheckReply:
    skillset, _, transition = command.partition(":")
    replies = [r for r in session.get(keys.check("spot_arm", keys.LOCAL_CLIENT), timeout=5.0,
                                      payload=encode(CheckRequest(skillset=skillset, transition=transition)))
               if r.ok is not None]
    assert len(replies) == 1, replies
    return decode(replies[0].ok.payload.to_bytes(), CheckReply)


def test_a_resync_while_a_manager_restart_is_pending_never_vouches_for_the_old_status(client_factory, spot_arm,
                                                                                      monkeypatch) -> None:
    """Spot's manager restarts (rmw_zenoh: its tokens leave and come back) and is slow to publish its new
    status.  The bridge knows its last status is outdated: its heartbeat says so at once, and it answers the
    resync queries of a running monitor and of one that starts meanwhile with an error, not with the old
    status (which the monitor used to adopt, live, answering from a marking the robot had left).  Both stay
    syncing, the check answers state_unknown, until the new status comes; then they follow it."""
    from services.bridge_ros2 import start_bridge
    from services.simulator.manager import Manager
    from skinet.ros.keys import KeyStyle

    system, typemap = spot_arm
    slow, answer = threading.Event(), threading.Event()
    status_request = Manager.status_request

    def slow_to_answer(self):  # type: ignore[no-untyped-def]
        if slow.is_set():
            answer.wait(20)
        return status_request(self)

    monkeypatch.setattr(Manager, "status_request", slow_to_answer)
    style = KeyStyle(rmw_zenoh=True, domain=12)
    asker = client_factory()
    simulator = Simulator(client_factory(), system, typemap, style=style)
    bridge = start_bridge(client_factory(), system, typemap, style=style, source="bridge_ros2/restart")
    first = start_monitor(client_factory(), system)
    second = None
    try:
        wait_until(first.synced, 10, "synced")
        simulator.drive(scenario(STANDING), speed=0)
        wait_until(sees(first, "spot", "posture", "Standing"), 10, "spot standing")
        reply = _ask(asker, "spot:sit_down.start")  # no predictor here: prediction_pending, never state_unknown
        assert (reply.enabled, reply.state_stale, [k for _, k, _ in kinds(reply)]) == (True, False,
                                                                                      ["prediction_pending"])
        slow.set()
        simulator.restart("spot")  # initial state: PowerOff, Sitting; its new status is slow to come
        outdated = ("'bridge_ros2/restart' has no current status of spot: its manager restarted (the manager (or "
                    "its gateway) came back): waiting for its new status")
        wait_until(lambda: first.snapshot().state.sync["spot"].state == "syncing", 2, "syncing at once")
        time.sleep(1.5)  # its resync queries (every second) are refused
        sync = first.snapshot().state.sync
        assert (sync["spot"].state, sync["spot"].reason, sync["manipulator"].state) == ("syncing", outdated, "live")
        reply = _ask(asker, "spot:sit_down.start")
        assert (reply.decision, reply.state_stale, ("", "state_unknown", "warn") in kinds(reply)) == ("warn", True,
                                                                                                       True)
        assert "spot syncing since" in reply.state_reason and outdated in reply.state_reason
        answers = list(asker.get(keys.resync("spot_arm", "spot"), timeout=5.0))
        assert [(a.ok, a.err.payload.to_bytes().decode()) for a in answers] == [(None, outdated)]
        # A monitor that starts now (its predecessor gone) asks at once: refused too.
        token = keys.alive("spot_arm", "monitor", first.instance_id)
        gone = LivelinessWatch(asker, token)
        first.close()
        first.session.close()
        gone.wait(lambda alive: token not in alive)
        gone.close()
        second = start_monitor(client_factory(), system, resync_timeout=0.5)
        wait_until(lambda: second.snapshot().state.sync["manipulator"].state == "live", 5, "the arm synced")
        time.sleep(1.0)
        assert second.snapshot().state.sync["spot"].state == "syncing"
        reply = _ask(asker, "spot:sit_down.start")
        assert (reply.decision, reply.state_stale, ("", "state_unknown", "warn") in kinds(reply)) == ("warn", True,
                                                                                                       True)
        answer.set()  # the new status comes: followed
        wait_until(second.synced, 5, "spot live again")
        assert second.snapshot().state.skillsets["spot"].resources == {
            "power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"}
        reply = _ask(asker, "spot:sit_down.start")
        assert (reply.enabled, reply.state_stale, [k for _, k, _ in kinds(reply)]) == (False, False,
                                                                                       ["prediction_pending"])
    finally:
        answer.set()
        if second is not None:
            second.close()
        first.close()
        bridge.close()
        simulator.close()
