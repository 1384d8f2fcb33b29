"""The bridge on bound skillsets, live on Zenoh (docs/semantics.md §9; services/bridge_ros2/bound_live.py, simulator/bound.py).

The Nav2 example's simulated robot speaks the real action and lifecycle protocols
(CDR requests and replies on send_goal / cancel_goal / get_result / get_state
queryables, GoalStatusArray in a transient-local cache, TransitionEvent and
BatteryState topics) on zenoh-bridge-ros2dds keys and on rmw_zenoh keys (type
hashes, attachments).  The chain (bridge, monitor, predictor) must give, step by
step, what the core replay gives, and the command check must warn before the two
unsafe commands of the run.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import pytest
import zenoh

from event_watch import Events
from services.bridge_ros2.bound_live import start_bound_bridge
from chains.chain import run_bound_chain
from services.common.zenoh_config import session_config
from services.simulator.bound import BoundSimulator
from skinet.system.load import load_bindings, load_system
from skinet.files.read import read_text
from skinet.mission.scenario import StepRecord, parse_scenario, replay
from skinet.ros.keys import KeyStyle
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import CheckReply, CheckRequest

REPO = Path(__file__).resolve().parents[2]
NAV2 = REPO / "examples" / "nav2"
FIRST = {"/battery_state": {"percentage": 0.9, "power_supply_status": 1}}


@pytest.fixture(scope="module")
def nav2():
    system, _ = load_system(NAV2 / "nav2.toml")
    bindings, _ = load_bindings(system)
    scenario = parse_scenario(read_text(NAV2 / "missions" / "nav2_run.toml"), "nav2_run.toml")
    return system, bindings, scenario


@pytest.fixture
def session():
    s = zenoh.open(session_config("peer", multicast_scouting=False))
    yield s
    s.close()


def comparable(records: list[StepRecord]) -> list[tuple]:
    return [(r.index, r.step.transition, r.holds, r.violations,
             [(w.skillset, w.transition, w.property, w.constraint) for w in r.warnings], r.unsafe_count, r.divergence)
            for r in records]


@pytest.mark.parametrize("style", [KeyStyle(), KeyStyle(namespace="/robot1"), KeyStyle(rmw_zenoh=True, domain=7)],
                         ids=["zenoh-bridge-ros2dds", "namespace", "rmw_zenoh"])
def test_the_nav2_run_through_the_chain(nav2, session, style: KeyStyle) -> None:
    """Every step as the core replay gives it, and the check (asked over Zenoh) warns before both commands."""
    system, bindings, scenario = nav2
    checks: list[tuple[int, str, list[tuple[str, str]]]] = []

    def on_record(record: StepRecord) -> None:
        if record.step.consider:
            replies = list(session.get(keys.check(system.name, keys.LOCAL_CLIENT), payload=encode(
                CheckRequest(skillset="nav2", transition=record.step.consider)), timeout=5))
            reply = decode(replies[0].ok.payload.to_bytes(), CheckReply)
            checks.append((record.index, reply.decision, [(r.property, r.constraint) for r in reply.reasons]))

    records = run_bound_chain(system, bindings, scenario, session=session, style=style, on_record=on_record)
    assert comparable(records) == comparable(replay(system, scenario))
    assert [(r.index, r.step.consider) for r in records if r.warnings] == [(3, "navigate.start"),
                                                                          (13, "navigate.start")]
    assert checks == [(3, "warn", [("stay_on_charger", "explicit")]), (13, "warn", [("dock_when_low", "explicit")])]
    assert all(r.divergence is None for r in records)


def test_start_up_reads_the_last_status_and_the_lifecycle_state(nav2, session) -> None:
    """The robot is busy before the bridge starts: its initial status shows the running goal (from the
    status cache), the active navigator (get_state) and the battery (its first sample).  Until the battery
    speaks, nothing is published: the skillset is syncing."""
    system, bindings, _ = nav2
    robot = BoundSimulator(session, system, bindings)
    events = Events(session, system.name)
    try:
        for transition in ("navigator_configured", "navigator_activated", "undock_robot.start",
                           "undock_robot.success.undocked"):
            assert robot.play("nav2", transition, None)
        assert robot.send_goal("nav2", "navigate", {"behavior_tree": "bt.xml"})
        bridge = start_bound_bridge(session, system, bindings, settle=0.1, retry=0.1)
        try:
            time.sleep(1.0)
            assert events.items == [] and bridge.feed.missing() == {
                "nav2": ["a first /battery_state message"]}
            robot.publish("nav2", "/battery_state", {"percentage": 0.1, "power_supply_status": 2})
            first = events.wait(lambda items: len(items) == 1)[0]
            assert (first.seq, first.transition, first.info) == (0, None, "initial status")
            assert first.status.model_dump() == {
                "resources": {"navigator": "Active", "motion": "Still", "dock": "Docked", "battery": "Low",
                              "charging": "NotCharging"}, "running": ["navigate"]}
            # The model did not see the undocking (it happened before): the monitor gets the robot as it is.
            robot.finish("nav2", "navigate", "success")
            got = events.wait(lambda items: len(items) == 2)[1]
            assert (got.transition, got.status.running) == ("navigate.success.arrived", [])
            # A monitor that missed events resyncs from the bridge's last status.
            replies = list(session.get(keys.resync(system.name, "nav2"), timeout=2))
            assert [decode(r.ok.payload.to_bytes(), type(first)).status.running for r in replies] == [[]]
        finally:
            bridge.close()
    finally:
        robot.close()


def test_an_action_server_that_never_had_a_goal_reads_as_idle_only_once_present(nav2, session) -> None:
    """An empty status cache says nothing until the server is known to be there (its route token)."""
    system, bindings, _ = nav2
    events = Events(session, system.name)
    bridge = start_bound_bridge(session, system, bindings, settle=0.1, retry=0.1)
    try:
        time.sleep(0.8)
        assert events.items == [] and "the status of /navigate_to_pose" in bridge.feed.missing()["nav2"]
        robot = BoundSimulator(session, system, bindings)
        try:
            robot.publish_topics(FIRST)
            got = events.wait(lambda items: len(items) == 1, timeout=5)[0]
            assert got.info == "initial status" and got.status.running == []
        finally:
            robot.close()
    finally:
        bridge.close()


def test_the_status_may_come_before_the_reply_to_send_goal(nav2, session) -> None:
    system, bindings, _ = nav2
    robot = BoundSimulator(session, system, bindings, status_first=True)
    events = Events(session, system.name)
    bridge = start_bound_bridge(session, system, bindings, settle=0.1, retry=0.1)
    try:
        robot.publish_topics(FIRST)
        events.wait(lambda items: len(items) == 1)
        for t in ("navigator_configured", "navigator_activated", "undock_robot.start", "undock_robot.success.undocked"):
            assert robot.play("nav2", t, None)
        assert robot.send_goal("nav2", "navigate")  # the reply came after the status: still accepted
        got = events.wait(lambda items: len(items) == 6)
        assert [e.transition for e in got] == [None, "navigator_configured", "navigator_activated",
                                               "undock_robot.start", "undock_robot.success.undocked", "navigate.start"]
    finally:
        bridge.close()
        robot.close()


def test_no_result_in_time_gives_the_default_mode_and_says_so(nav2, session, caplog) -> None:
    """The get_result server does not answer when the goal aborts: after --hold the binding's default mode,
    with a warning; the later lifecycle event still comes, after it."""
    system, bindings, _ = nav2
    robot = BoundSimulator(session, system, bindings)
    events = Events(session, system.name)
    bridge = start_bound_bridge(session, system, bindings, settle=0.1, retry=0.1, hold=0.3)
    try:
        robot.publish_topics(FIRST)
        events.wait(lambda items: len(items) == 1)
        for t in ("navigator_configured", "navigator_activated", "undock_robot.start", "undock_robot.success.undocked",
                  "navigate.start"):
            assert robot.play("nav2", t, None)
        events.wait(lambda items: len(items) == 6)
        robot.actions[("nav2", "navigate")].queryables[2].undeclare()  # get_result, replaced by a silent one
        held: list[zenoh.Query] = []
        silent = session.declare_queryable("navigate_to_pose/_action/get_result", held.append)
        with caplog.at_level(logging.INFO, logger="skinet.bridge_ros2"):
            started = time.monotonic()
            assert robot.finish("nav2", "navigate", "failure", {"error_code": 9003})
            robot.play("nav2", "navigator_deactivated", None)
            got = events.wait(lambda items: len(items) == 8)
        assert time.monotonic() - started >= 0.3 and len(held) == 1
        silent.undeclare()
        held.clear()
        assert [e.transition for e in got[6:]] == ["navigate.failure.failed", "navigator_deactivated"]
        assert "no reply from /navigate_to_pose/_action/get_result within 0.30 s" in caplog.text
        assert "result not received in time: mode 'failed' (the binding's default)" in caplog.text
    finally:
        bridge.close()
        robot.close()


def test_bad_payloads_are_counted_and_logged_once_and_the_bridge_goes_on(nav2, session, caplog) -> None:
    system, bindings, _ = nav2
    robot = BoundSimulator(session, system, bindings)
    events = Events(session, system.name)
    bridge = start_bound_bridge(session, system, bindings, settle=0.1, retry=0.1)
    try:
        robot.publish_topics(FIRST)
        events.wait(lambda items: len(items) == 1)
        with caplog.at_level(logging.WARNING, logger="skinet.bridge_ros2"):
            for _ in range(3):
                session.put("navigate_to_pose/_action/status", b"\x00\x01\x00\x00\xff")
                session.put("battery_state", b"not cdr")
            robot.play("nav2", "navigator_configured", None)
            got = events.wait(lambda items: len(items) == 2)
        assert got[1].transition == "navigator_configured"
        assert bridge.counters.malformed == 6
        lines = [r.getMessage() for r in caplog.records if "does not decode" in r.getMessage()]
        assert len(lines) == 2 and all("reported once per kind" in line for line in lines)
    finally:
        bridge.close()
        robot.close()


def test_the_bridge_command_replays_a_bag_of_a_bound_robot(nav2, session, tmp_path: Path, router, client,
                                                            zenoh_args) -> None:
    """``python -m services.bridge_ros2 nav2.toml --replay BAG`` publishes the events of the run, then exits."""
    import subprocess
    import sys

    from services.bridge_ros2.record import BagRecorder, recorded_topics

    system, bindings, scenario = nav2
    bag = tmp_path / "run"
    recorder = BagRecorder(session, bag, recorded_topics(system, {}, bindings), heard_only=True)
    robot = BoundSimulator(session, system, bindings)
    robot.publish_topics(scenario.topics)
    robot.drive(scenario, speed=0, on_step=lambda _: time.sleep(0.02))
    time.sleep(0.2)
    recorder.close()
    robot.close()
    events = Events(client, system.name)
    time.sleep(0.3)
    done = subprocess.run([sys.executable, "-m", "services.bridge_ros2", str(NAV2 / "nav2.toml"), "--replay", str(bag),
                           *zenoh_args], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    got = events.wait(lambda items: len(items) == sum(s.transition is not None for s in scenario.steps))
    assert [e.transition for e in got] == [s.transition.replace("timed_out", "failed") for s in scenario.steps
                                           if s.transition]  # no result in a bag: the default failure mode
    assert ("bound skillsets: 21 messages, 12 events, 0 model divergences, 0 malformed, 0 resyncs after a gap, "
            "1 result not recorded") in done.stderr


def test_a_bad_binding_stops_the_bridge_command_with_one_line(tmp_path: Path) -> None:
    import subprocess
    import sys

    (tmp_path / "nav2.rl").write_text((NAV2 / "nav2.rl").read_text())
    (tmp_path / "s.toml").write_text('[system]\nname = "s"\n[[skillsets]]\nmodel = "nav2.rl"\nbinding = "b.toml"\n')
    (tmp_path / "b.toml").write_text('[skills.navigate]\naction = "/navigate_to_pose"\n'
                                     'type = "nav2_msgs/action/NavigateToPose"\n')
    done = subprocess.run([sys.executable, "-m", "services.bridge_ros2", str(tmp_path / "s.toml")], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [
        f"{tmp_path / 'b.toml'}:3:9: error: unknown action type 'nav2_msgs/action/NavigateToPose' (expected one of: "
        "none); put its .action file in the binding's definitions folder as <package>/action/<Name>.action"]


def test_simulator_and_bridge_commands_on_rmw_zenoh_keys(nav2, client, zenoh_args, spawn, tmp_path: Path) -> None:
    """``python -m services.simulator nav2_run.toml --rmw-zenoh`` and ``python -m services.bridge_ros2 nav2.toml
    --rmw-zenoh`` as separate processes through a router: every transition of the run, in order."""
    import subprocess
    import sys

    system, _, scenario = nav2
    events = Events(client, system.name)
    ros = ["--rmw-zenoh", "--domain", "5"]
    spawn("services.bridge_ros2", str(NAV2 / "nav2.toml"), *ros, "--settle", "0.2", *zenoh_args)
    sim = subprocess.run([sys.executable, "-m", "services.simulator", str(NAV2 / "missions" / "nav2_run.toml"), *ros,
                          "--speed", "0", "--start-delay", "2", "--linger", "1", *zenoh_args], cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    assert sim.returncode == 0, sim.stdout + sim.stderr
    steps = [line for line in sim.stdout.splitlines() if line.startswith("step ")]
    assert len(steps) == len(scenario.steps) and not any(line.endswith("(no effect)") for line in steps)
    assert steps[3].split()[4:6] == ["start", "nav2:undock_robot.start"] and " goal " in steps[3]
    transitions = [s.transition for s in scenario.steps if s.transition]
    got = events.wait(lambda items: len(items) == 1 + len(transitions), timeout=20)
    assert [e.transition for e in got] == [None] + transitions
    assert got[0].info == "initial status"


def mixed_system(tmp_path: Path) -> Path:
    """Spot behind its skillset manager and the Nav2 base through its binding, in one system."""
    path = tmp_path / "mixed.toml"
    path.write_text(f'''[system]
name = "mixed"
properties = "{NAV2 / 'nav2.props'}"
types = "{REPO / 'skillsets' / 'spot_arm.types.json'}"

[[skillsets]]
model = "{REPO / 'skillsets' / 'spot.rl'}"
manager = "/spot/spot_skillset_manager"

[[skillsets]]
model = "{NAV2 / 'nav2.rl'}"
binding = "{NAV2 / 'nav2.binding.toml'}"
''')
    return path


def test_messages_of_a_manager_and_a_bound_skillset_keep_their_arrival_order(client_factory, zenoh_args, spawn,
                                                                             tmp_path: Path) -> None:
    """``python -m services.bridge_ros2`` serves Spot's manager and the Nav2 base's binding: their messages,
    interleaved at full speed through a router, give events in the same interleaving (each kind had its own
    thread, so they came in whatever order the two threads published them)."""
    from services.bridge_ros2.bound import BoundFeed
    from services.bridge_ros2.feed import Feed
    from services.bridge_ros2.order import Order
    from services.simulator.manager import Manager
    from skinet.system.load import load_typemap
    from skinet.ros.actions import message
    from skinet.ros.typestore import encode as cdr
    from tests.services.test_bridge import CYCLES

    path = mixed_system(tmp_path)
    system, _ = load_system(path)
    bindings, _ = load_bindings(system)
    typemap = load_typemap(path)
    order = Order()  # the expected events: both feeds, one order, the same messages in the same order
    feed = Feed(system, typemap, "bridge_ros2/m", order=order)
    bound = BoundFeed(system, bindings, "bridge_ros2/m", synced=True, results=False, order=order)
    spot = Manager(system.component("spot").skillset, feed.managers["spot"].store, info="spot")
    messages = spot.status_request()
    for i in range(120):
        skill, outcome = CYCLES["spot"][i % len(CYCLES["spot"])]
        messages += spot.raise_event(skill) if outcome is None else \
            spot.skill_request(skill, f"spot-{i}") + spot.terminate(skill, "success", outcome)
    topics = {t.topic: t for t in feed.managers["spot"].topics}
    style = KeyStyle()
    store = bindings["nav2"].store
    battery = "sensor_msgs/msg/BatteryState"
    stream = []  # (key, CDR, feed it)
    for n, m in enumerate(m for m in messages if m.topic in topics):
        t, data = topics[m.topic], cdr(feed.managers["spot"].store, m.typename, m.msg)
        stream.append((style.key("/spot/spot_skillset_manager", t), data, lambda t=t, d=data: feed.feed("spot", t, d)))
        data = cdr(store, battery, message(store, battery, {"percentage": 0.1 if n % 2 == 0 else 0.9,
                                                            "power_supply_status": 1}))
        stream.append((style.name_key("/battery_state", battery), data,
                       lambda d=data: bound.feed("/battery_state", d, 0.0)))
    expected = [(ev.skillset, ev.transition) for _, _, fed in stream for ev in fed()]
    assert len(expected) > 500 and sum(a[0] != b[0] for a, b in zip(expected, expected[1:])) > 250

    robot = BoundSimulator(client_factory(), system, bindings)  # the base's servers, node and first battery level
    watcher, publisher = client_factory(), client_factory()
    events = Events(watcher, system.name)
    alive = keys.alive("mixed", "bridge_ros2", "m")
    spawn("services.bridge_ros2", str(path), "--instance", "m", "--settle", "0.1", *zenoh_args)
    deadline = time.monotonic() + 30
    while not [r for r in watcher.liveliness().get(alive, timeout=1) if r.ok is not None]:
        assert time.monotonic() < deadline, "the bridge did not start"
        time.sleep(0.1)
    pubs = {key: publisher.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
            for key, _, _ in stream}
    time.sleep(0.3)  # the bridge's subscriptions reach the router
    robot.publish_topics(FIRST)
    first = events.wait(lambda items: len(items) == 1, timeout=10)[0]
    assert (first.skillset, first.info) == ("nav2", "initial status")
    for key, data, _ in stream:
        pubs[key].put(data)
    got = events.wait(lambda items: len(items) >= len(expected) + 1, timeout=30)[1:]
    robot.close()
    assert [(e.skillset, e.transition) for e in got] == expected
    for name, first_seq in (("spot", 0), ("nav2", 1)):  # one stream per skillset, one epoch for both kinds
        seqs = [e.seq for e in got if e.skillset == name]
        assert seqs == list(range(first_seq, first_seq + len(seqs)))
    assert len({e.epoch for e in got}) == 1


def test_a_bound_skillset_waiting_for_a_result_holds_the_later_events_of_a_manager(tmp_path: Path) -> None:
    """One order for both kinds: a dock goal ABORTED waits for its result (its mode depends on it), and Spot's
    status that came after waits behind it, at most until the result (or its timeout) comes."""
    from services.bridge_ros2.bound import BoundFeed
    from services.bridge_ros2.feed import Feed
    from services.bridge_ros2.order import Order
    from services.simulator.manager import Manager
    from services.simulator.protocols import ABORTED, ACCEPTED, SUCCEEDED, ActionLogic, Goal
    from skinet.system.load import load_typemap
    from skinet.ros.bound import ResultRequest
    from skinet.ros.typestore import encode as cdr

    path = mixed_system(tmp_path)
    system, _ = load_system(path)
    bindings, _ = load_bindings(system)
    order = Order()
    feed = Feed(system, load_typemap(path), "bridge_ros2/m", order=order)
    bound = BoundFeed(system, bindings, "bridge_ros2/m", synced=True, order=order)
    store = bindings["nav2"].store
    servers = {skill: ActionLogic(store, bindings["nav2"].skill(skill).type) for skill in ("undock_robot", "dock_robot")}

    def status(skill: str, goal: bytes, code: int) -> list[tuple[str, str | None]]:
        servers[skill].goals[goal] = Goal(goal, 1.0, code)
        return [(e.skillset, e.transition) for e in bound.feed(f"/{skill}/_action/status",
                                                               servers[skill].status_array(), 1.0)]

    assert status("undock_robot", b"a" * 16, ACCEPTED) == [("nav2", "undock_robot.start")]
    assert status("undock_robot", b"a" * 16, SUCCEEDED) == [("nav2", "undock_robot.success.undocked")]
    assert status("dock_robot", b"b" * 16, ACCEPTED) == [("nav2", "dock_robot.start")]
    assert status("dock_robot", b"b" * 16, ABORTED) == []  # its result names the mode: it waits
    assert bound.take_requests() == [("nav2", ResultRequest("dock_robot", "/dock_robot",
                                                            "opennav_docking_msgs/action/DockRobot", b"b" * 16))]
    spot = Manager(system.component("spot").skillset, feed.managers["spot"].store, info="spot")
    initial = spot.status_request()[0]
    topic = next(t for t in feed.managers["spot"].topics if t.kind == "status")
    assert feed.feed("spot", topic, cdr(feed.managers["spot"].store, initial.typename, initial.msg)) == []
    got = bound.result("nav2", ResultRequest("dock_robot", "/dock_robot", "opennav_docking_msgs/action/DockRobot",
                                             b"b" * 16), None, 2.0)  # no reply in time: the default mode
    assert [(e.skillset, e.transition) for e in got] == [("nav2", "dock_robot.failure.failed"), ("spot", None)]


def _resync(session: zenoh.Session, system: str, skillset: str) -> tuple[str, object]:
    """('ok', the status) or ('err', the reason) of a resync query, as a monitor gets it."""
    from skinet.wire.messages import CanonicalEvent

    replies = list(session.get(keys.resync(system, skillset), timeout=2))
    assert len(replies) == 1, replies
    if replies[0].ok is None:
        return "err", replies[0].err.payload.to_bytes().decode()
    return "ok", decode(replies[0].ok.payload.to_bytes(), CanonicalEvent).status


def _pending(session: zenoh.Session, system: str, timeout: float = 3.0) -> dict[str, str]:
    """The ``pending`` of the next heartbeat on ``system``."""
    from skinet.wire.messages import Heartbeat

    got: list[Heartbeat] = []
    sub = session.declare_subscriber(keys.heartbeat(system), lambda s: got.append(decode(s.payload.to_bytes(),
                                                                                           Heartbeat)))
    deadline = time.monotonic() + timeout
    while not got and time.monotonic() < deadline:
        time.sleep(0.01)
    sub.undeclare()
    assert got, "no heartbeat"
    return got[0].pending


def test_a_bound_skillset_is_pending_until_every_interface_is_read_again(nav2, session) -> None:
    """docs/semantics.md §7 for bindings: before its first readings, and after an action server or a lifecycle node left,
    the bridge refuses to vouch for the skillset's status (heartbeat ``pending``, resync queries refused) until
    the interface is read again; that reading shows what the restart did (the goal forgotten, the node
    unconfigured: divergences), and an event closes the gap."""
    from skinet.ros.bound import goal_text
    from skinet.wire.messages import Heartbeat
    from tests.services.test_monitor import wait_until

    system, bindings, _ = nav2
    robot = BoundSimulator(session, system, bindings)
    events = Events(session, system.name)
    bridge = start_bound_bridge(session, system, bindings, settle=1.0, retry=0.1, source="bridge_ros2/b")
    try:
        time.sleep(1.8)  # the servers settled and their caches were read; the battery has not spoken
        waiting = ("'bridge_ros2/b' has no current status of nav2: waiting for a first /battery_state message")
        assert _resync(session, "nav2", "nav2") == ("err", waiting)  # (no reply at all, before)
        assert _pending(session, "nav2") == {"nav2": waiting[len("'bridge_ros2/b' has no current status of nav2: "):]}
        robot.publish_topics(FIRST)
        events.wait(lambda items: len(items) == 1)
        for transition in ("navigator_configured", "navigator_activated", "undock_robot.start",
                           "undock_robot.success.undocked", "navigate.start"):
            assert robot.play("nav2", transition, {"behavior_tree": "bt.xml"} if transition == "navigate.start"
                              else None)
        events.wait(lambda items: len(items) == 6)
        assert _pending(session, "nav2") == {} and _resync(session, "nav2", "nav2")[0] == "ok"
        beats: list[tuple[float, dict[str, str]]] = []  # (when, pending) of every heartbeat from now on
        heard = session.declare_subscriber(keys.heartbeat("nav2"), lambda s: beats.append(
            (time.monotonic(), decode(s.payload.to_bytes(), Heartbeat).pending)))
        robot.restart_server("nav2", "navigate")  # it forgets the running goal
        restarted = time.monotonic()
        left = "the action server of /navigate_to_pose left: waiting for the status of /navigate_to_pose"
        wait_until(lambda: any(p == {"nav2": left} for _, p in beats), 1.0, "pending")  # sent at once, not after 0.5 s
        assert _resync(session, "nav2", "nav2") == ("err", f"'bridge_ros2/b' has no current status of nav2: {left}")
        got = events.wait(lambda items: len(items) == 8)[6:]
        wait_until(lambda: beats[-1][1] == {}, 1.0, "no longer pending, at once")
        heard.undeclare()
        assert next(t for t, p in beats if p) - restarted < 0.4
        assert [(e.transition, e.status.running, e.info.split(":")[0]) for e in got] == [
            (None, [], "model divergence"), (None, [], "resync after the action server of /navigate_to_pose left; "
                                                       "state now differs")]
        goal = goal_text(robot.sent[("nav2", "navigate")])
        assert [e.info for e in got] == [
            f"model divergence: /navigate_to_pose/_action/status: goal {goal} absent: navigate no longer runs it, but "
            "no outcome of it was seen (did the action server restart?)",
            "resync after the action server of /navigate_to_pose left; state now differs: navigate no longer running"]
        assert _pending(session, "nav2") == {} and _resync(session, "nav2", "nav2")[0] == "ok"
        robot.restart_node("nav2", "navigator")  # unconfigured again
        got = events.wait(lambda items: len(items) == 10)[8:]
        assert [e.status.resources["navigator"] for e in got] == ["Unconfigured", "Unconfigured"]
        assert got[0].info == ("model divergence: /bt_navigator/get_state: unconfigured (navigator Active -> "
                               "Unconfigured): navigator became Unconfigured, but no event of the model takes "
                               "navigator from Active to Unconfigured here")
        assert got[1].info == "resync after the lifecycle node /bt_navigator left; state now differs: navigator " \
                              "Active -> Unconfigured"
        assert bridge.counters.resyncs == 2 and _pending(session, "nav2") == {}
    finally:
        bridge.close()
        robot.close()


def test_the_monitor_reports_each_drift_with_the_message_that_showed_it(nav2, session) -> None:
    """docs/semantics.md §9: a drift is a model divergence, with the message that showed it.  The monitor's LiveState (the
    dashboard's and ``skinet watch``'s list of divergences) used to say only that the transition was not
    enabled, and a drift that moved nothing (a second goal, a value matching no state) never reached it."""
    from services.monitor import start_monitor
    from skinet.ros.bound import goal_text
    from skinet.wire.messages import LiveState
    from tests.services.test_monitor import wait_until

    system, bindings, _ = nav2
    robot = BoundSimulator(session, system, bindings)
    bridge = start_bound_bridge(session, system, bindings, settle=0.1, retry=0.1)
    monitor = start_monitor(session, system)
    states: list[LiveState] = []
    sub = session.declare_subscriber(keys.state("nav2"), lambda s: states.append(decode(s.payload.to_bytes(),
                                                                                       LiveState)))
    try:
        robot.publish_topics(FIRST)
        wait_until(monitor.synced, 10, "synced")
        robot.send_goal("nav2", "navigate")  # the navigator is still unconfigured: the model forbids it
        first = goal_text(robot.sent[("nav2", "navigate")])
        robot.send_goal("nav2", "navigate")  # a second goal while the first runs
        second = goal_text(robot.sent[("nav2", "navigate")])
        robot.publish("nav2", "/battery_state", {"percentage": float("nan"), "power_supply_status": 1})
        wait_until(lambda: monitor.counters.divergences == 3, 10, "three divergences")
        time.sleep(0.2)
        nav = "/navigate_to_pose/_action/status"
        assert [(s.event.rsplit("#", 1)[0], s.divergence) for s in states if s.divergence] == [
            ("nav2:navigate.start", f"{nav}: goal {first} ACCEPTED: navigate started, but the model says navigate "
                                    "cannot start: precondition 'active' (navigator == Active) false (navigator is "
                                    "Unconfigured, motion is Still, dock is Docked, battery is Ok, charging is "
                                    "Charging) ('navigate.start' is not enabled in the live marking; observed "
                                    "marking adopted)"),
            ("nav2:status", f"{nav}: goal {second} ACCEPTED: a second goal of navigate, but navigate already runs "
                            f"goal {first} (one goal at a time per skill)"),
            ("nav2:status", "/battery_state: percentage=nan: battery observed, but no state of battery matches")]
        assert monitor.snapshot().state.skillsets["nav2"].running == ["navigate"]
        # The run's list (dashboard, watch): the monitor's reason, or the bridge's drift, beside the bridge's words.
        def listed() -> list:  # violation onsets are listed too (issue 30): the divergences here
            return [e for e in monitor.divergences().entries if e.kind == "divergence"]

        wait_until(lambda: len(listed()) == 3, 5, "the list published")
        drifts = [s.divergence for s in states if s.divergence]
        first_drift = drifts[0].split(" ('navigate.start' is not enabled")[0]
        assert [(e.kind, e.event.rsplit("#", 1)[0], e.reason, e.info) for e in listed()] == [
            ("divergence", "nav2:navigate.start", "'navigate.start' is not enabled in the live marking; observed "
                                                  "marking adopted", f"model divergence: {first_drift}"),
            ("divergence", "nav2:status", drifts[1], f"model divergence: {drifts[1]}"),
            ("divergence", "nav2:status", drifts[2], f"model divergence: {drifts[2]}")]
    finally:
        sub.undeclare()
        monitor.close()
        bridge.close()
        robot.close()
