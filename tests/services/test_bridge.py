"""bridge_ros2: simulated managers -> canonical events, live on Zenoh and from rosbag2 files.

Key mapping (skinet.ros.keys) first, then the simulator and the bridge on client
sessions of a loopback router, a recording of the managers' topics written as
sqlite3 and mcap bags and replayed, the start-up status request, and the two
command-line programs.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from services.bridge_ros2 import replay_bag, start_bridge
from services.common.zenoh_config import session_config
from services.simulator import Simulator
from skinet.live import LiveSystem
from skinet.mission import parse_scenario
from skinet.ros.keys import (
    KeyStyle, bridge_key, dds_type_name, manager_topics, parse_rmw_attachment, rmw_attachment, rmw_zenoh_key,
    topic_fqn,
)
from skinet.ros.typestore import build_typestore
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import CanonicalEvent

REPO = Path(__file__).resolve().parents[2]
SOURCE = "bridge_ros2/test"

# -- key mapping ----------------------------------------------------------------------------


def test_bridge_keys():
    assert topic_fqn("/spot/spot_skillset_manager", "spot_skillset/status") == \
        "/spot/spot_skillset_manager/spot_skillset/status"
    assert bridge_key("/spot/spot_skillset_manager", "spot_skillset/status") == \
        "spot/spot_skillset_manager/spot_skillset/status"
    assert bridge_key("/spot/spot_skillset_manager", "spot_skillset/status", "/robot1/") == \
        "robot1/spot/spot_skillset_manager/spot_skillset/status"
    with pytest.raises(ValueError):
        topic_fqn("/", "spot_skillset/status")


def test_rmw_zenoh_keys_and_attachment(spot_arm):
    system, typemap = spot_arm
    comp = system.component("spot")
    store = build_typestore(comp.skillset, typemap)
    status = next(t for t in manager_topics(comp.skillset) if t.kind == "status")
    assert dds_type_name("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert rmw_zenoh_key("/robot1", "chatter", "std_msgs/msg/String", "RIHS01_df66") == \
        "0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df66"
    key = KeyStyle(rmw_zenoh=True, domain=2).key(comp.manager, status, store)
    head = "2/spot/spot_skillset_manager/spot_skillset/status/spot_skillset_interfaces::msg::dds_::SkillsetStatus_/"
    assert key.startswith(head + "RIHS01_") and len(key) == len(head) + 7 + 64
    assert KeyStyle(rmw_zenoh=True).key(comp.manager, status).endswith("SkillsetStatus_/*")
    # Humble's std_msgs/Empty has this RIHS01 hash in rmw_zenoh's keys.
    assert store.hash_rihs01("std_msgs/msg/Empty") == \
        "RIHS01_20b625256f32d5dbc0d04fee44f43c41e51c70d3502f84b4a08e7a9c26a96312"
    att = rmw_attachment(7, 1_700_000_000_123_456_789, bytes(range(16)))
    assert len(att) == 33 and parse_rmw_attachment(att) == (7, 1_700_000_000_123_456_789, bytes(range(16)))
    with pytest.raises(ValueError):
        parse_rmw_attachment(att[:-1])


@pytest.mark.parametrize("style", [KeyStyle(), KeyStyle(namespace="r1"), KeyStyle(rmw_zenoh=True, domain=3)])
def test_one_subscription_covers_every_topic(spot_arm, style: KeyStyle):
    system, typemap = spot_arm
    comp = system.component("manipulator")
    store = build_typestore(comp.skillset, typemap)
    wildcard = zenoh.KeyExpr(style.all_topics(comp.manager, comp.skillset))
    for t in manager_topics(comp.skillset):
        key = style.key(comp.manager, t, store)
        assert wildcard.intersects(zenoh.KeyExpr(key)) and style.topic(comp.manager, key) == t.topic
    assert style.topic("/other/node", style.key(comp.manager, manager_topics(comp.skillset)[0], store)) is None


# -- live chain -----------------------------------------------------------------------------


class Events:
    """Canonical events of a system, in arrival order."""

    def __init__(self, session: zenoh.Session, system: str):
        self.items: list[CanonicalEvent] = []
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(keys.events(system, "*"), self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.items.append(decode(sample.payload.to_bytes(), CanonicalEvent))
            self._cond.notify_all()

    def wait(self, predicate: Callable[[list[CanonicalEvent]], bool], timeout: float = 5.0) -> list[CanonicalEvent]:
        with self._cond:
            assert self._cond.wait_for(lambda: predicate(self.items), timeout), self.items
            return list(self.items)

    def of(self, skillset: str) -> list[CanonicalEvent]:
        with self._cond:
            return [e for e in self.items if e.skillset == skillset]


class Recorder:
    """Every sample of the managers' topics with its arrival time: a ``ros2 bag record``."""

    def __init__(self, session: zenoh.Session, system, style: KeyStyle = KeyStyle()):
        self.samples: list[tuple[int, str, str, str, bytes]] = []  # ns, skillset, fqn, typename, CDR
        self._lock = threading.Lock()
        self._subs = []
        for c in system.components:
            topics = {t.topic: t for t in manager_topics(c.skillset)}

            def on_sample(sample, c=c, topics=topics):
                t = topics.get(style.topic(c.manager, str(sample.key_expr)) or "")
                if t is not None:
                    with self._lock:
                        stamp = max(time.time_ns(), self.samples[-1][0] + 1 if self.samples else 0)
                        self.samples.append((stamp, c.name, topic_fqn(c.manager, t.topic), t.typename,
                                             sample.payload.to_bytes()))

            self._subs.append(session.declare_subscriber(style.all_topics(c.manager, c.skillset), on_sample))

    def write(self, path: Path, plugin: StoragePlugin, system, typemap) -> Path:
        stores = {c.name: build_typestore(c.skillset, typemap) for c in system.components}
        with self._lock:
            samples = list(self.samples)
        with Writer(path, version=9, storage_plugin=plugin) as writer:
            connections = {}
            for stamp, ss, fqn, typename, data in samples:
                if fqn not in connections:  # stores the generated message definitions
                    connections[fqn] = writer.add_connection(fqn, typename, typestore=stores[ss])
                writer.write(connections[fqn], stamp, data)
        return path


CHAIN = """
[scenario]
name = "chain"
system = "spot_arm.toml"

[[steps]]
skillset = "spot"
transition = "init_power.start"
[[steps]]
skillset = "spot"
transition = "init_power.success.powered_on"
[[steps]]
skillset = "spot"
transition = "stand_up.start"
[[steps]]
skillset = "spot"
transition = "stand_up.success.standing"
[[steps]]
skillset = "spot"
transition = "teleop.start"
[[steps]]
skillset = "spot"
transition = "teleop.start"
note = "rejected: ALREADY_RUNNING"
[[steps]]
skillset = "spot"
transition = "go_to_waypoint.start"
note = "rejected: PRECONDITION_FAILURE (control_mode Busy)"
[[steps]]
skillset = "manipulator"
transition = "arm_ready.start"
[[steps]]
skillset = "spot"
transition = "power_switchoff"
note = "teleop's invariants fail (cascade)"
[[steps]]
skillset = "spot"
transition = "power_switchoff"
note = "refused: GUARD_FAILURE"
[[steps]]
skillset = "manipulator"
transition = "arm_ready.interrupt"
note = "interrupting true: INTERRUPTING first"
[[steps]]
skillset = "manipulator"
transition = "arm_moving_to_RD.start"
[[steps]]
skillset = "manipulator"
transition = "arm_emergency_stop"
note = "the in_motion invariant stops arm_moving_to_RD (cascade)"
[[steps]]
skillset = "manipulator"
transition = "arm_moving_to_RD.failure.blocked"
note = "no effect: not running any more"
"""

OFF_SITTING = {"power_status": "PowerOff", "posture": "Sitting"}
EXPECTED = {
    "spot": [
        (None, {**OFF_SITTING, "control_mode": "Idle"}, [], "initial status"),
        ("init_power.start", {**OFF_SITTING, "control_mode": "Busy"}, ["init_power"], ""),
        ("init_power.success.powered_on", {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Idle"}, [], ""),
        ("stand_up.start", {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Busy"}, ["stand_up"], ""),
        ("stand_up.success.standing", {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Idle"}, [], ""),
        ("teleop.start", {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"}, ["teleop"], ""),
        ("power_switchoff", {**OFF_SITTING, "control_mode": "Idle"}, [], "invariant failures: teleop.inv.upright"),
    ],
    "manipulator": [
        (None, {"mutex": "Free", "arm_status": "HP"}, [], "initial status"),
        ("arm_ready.start", {"mutex": "Busy", "arm_status": "Moving"}, ["arm_ready"], ""),
        ("arm_ready.interrupt", {"mutex": "Free", "arm_status": "Away"}, [], ""),
        ("arm_moving_to_RD.start", {"mutex": "Busy", "arm_status": "Moving"}, ["arm_moving_to_RD"], ""),
        ("arm_emergency_stop", {"mutex": "Free", "arm_status": "Away"}, [],
         "invariant failures: arm_moving_to_RD.inv.in_motion"),
    ],
}
EXPECTED_COUNT = sum(len(v) for v in EXPECTED.values())


def view(ev: CanonicalEvent) -> tuple:
    return ev.transition, ev.status.resources if ev.status else None, ev.status.running if ev.status else None, ev.info


def run_chain(sessions: Callable[[], zenoh.Session], spot_arm, style: KeyStyle = KeyStyle()) -> tuple[Events, Recorder]:
    """Simulator, bridge and a watcher on three sessions from ``sessions``; the CHAIN scenario played."""
    system, typemap = spot_arm
    sim_session, bridge_session, watcher = sessions(), sessions(), sessions()
    events = Events(watcher, system.name)
    recorder = Recorder(watcher, system, style)
    sim = Simulator(sim_session, system, typemap, style=style)
    time.sleep(0.3)  # the watcher's subscriptions reach the router
    bridge = start_bridge(bridge_session, system, typemap, style=style, source=SOURCE)
    events.wait(lambda items: len(items) >= 2)  # each manager answered the bridge's status_request
    runs = sim.drive(parse_scenario(CHAIN, "chain.toml"), speed=0)
    assert [r.ok for r in runs] == [True, True, True, True, True, False, False, True, True, True, True, True,
                                    True, False], runs
    assert bridge.wait_statuses(sim.statuses_published())  # the bridge has caught up
    events.wait(lambda items: len(items) >= EXPECTED_COUNT)
    time.sleep(0.2)  # nothing more comes
    bridge.close()
    sim.close()
    return events, recorder


def check_chain(events: Events, spot_arm) -> None:
    """The exact expected events, numbered per skillset, which the live nets follow without divergence."""
    assert len(events.items) == EXPECTED_COUNT
    live = LiveSystem(spot_arm[0])
    for ss, expected in EXPECTED.items():
        got = events.of(ss)
        assert [view(e) for e in got] == expected
        assert [e.seq for e in got] == list(range(len(expected)))
        assert {(e.system, e.source) for e in got} == {("spot_arm", SOURCE)}
        for e in got:
            outcome = live.apply(e.skillset, e.transition, e.status.model_dump() if e.status else None)
            assert outcome.divergence is None, (e, outcome)


def test_simulator_to_bridge_exact_events(client_factory, spot_arm):
    events, _ = run_chain(client_factory, spot_arm)
    check_chain(events, spot_arm)


def test_one_shared_peer_session(spot_arm):
    """Embedded: simulator, bridge and their listeners on a single session (SPEC §1, §7)."""
    session = zenoh.open(session_config("peer", multicast_scouting=False))
    try:
        events, _ = run_chain(lambda: session, spot_arm)
        check_chain(events, spot_arm)
    finally:
        session.close()


def test_rmw_zenoh_chain(client_factory, spot_arm):
    events, recorder = run_chain(client_factory, spot_arm, KeyStyle(rmw_zenoh=True, domain=1))
    check_chain(events, spot_arm)
    assert recorder.samples and all(fqn.startswith(("/spot/", "/kinova/")) for _, _, fqn, _, _ in recorder.samples)


@pytest.mark.parametrize("plugin", [StoragePlugin.SQLITE3, StoragePlugin.MCAP], ids=["sqlite3", "mcap"])
def test_rosbag_replay_equals_live(client_factory, spot_arm, tmp_path: Path, plugin: StoragePlugin):
    system, typemap = spot_arm
    events, recorder = run_chain(client_factory, spot_arm)
    bag = recorder.write(tmp_path / f"session_{plugin.name.lower()}", plugin, system, typemap)
    with AnyReader([bag]) as reader:  # the bag carries the generated definitions: readable without our store
        conn = next(c for c in reader.connections if c.topic == "/spot/spot_skillset_manager/spot_skillset/status")
        assert "spot_skillset_interfaces/SkillTeleopStatus skill_teleop" in conn.msgdef.data
        assert conn.digest.startswith("RIHS01_")
        _, _, raw = next(reader.messages(connections=[conn]))
        assert reader.deserialize(raw, conn.msgtype).info == "/spot/spot_skillset_manager"
    replayed: list[CanonicalEvent] = []
    feed = replay_bag(bag, system, typemap, replayed.append, source=SOURCE)
    for ss in EXPECTED:
        # stamps, seqs and infos too; each run of a feed has an epoch of its own
        assert [e.model_copy(update={"epoch": 0}) for e in replayed if e.skillset == ss] == [
            e.model_copy(update={"epoch": 0}) for e in events.of(ss)]
        assert len({e.epoch for e in replayed} | {e.epoch for e in events.of(ss)}) == 2
    assert feed.counters.malformed == 0
    # In real time the replay takes as long as the recording.
    span = (recorder.samples[-1][0] - recorder.samples[0][0]) * 1e-9
    started = time.monotonic()
    again: list[CanonicalEvent] = []
    replay_bag(bag, system, typemap, again.append, source=SOURCE, realtime=True)
    assert time.monotonic() - started >= span * 0.9
    assert [e.model_copy(update={"epoch": 0}) for e in again] == [e.model_copy(update={"epoch": 0}) for e in replayed]


def test_bridge_learns_the_current_status_at_start_up(client_factory, spot_arm):
    """The status QoS is volatile: a late bridge must ask the manager (status_request)."""
    system, typemap = spot_arm
    sim_session, bridge_session, watcher = client_factory(), client_factory(), client_factory()
    sim = Simulator(sim_session, system, typemap)
    scenario = parse_scenario(CHAIN, "chain.toml")
    first = scenario.__class__(scenario.name, scenario.system, scenario.steps[:3])  # powered, stand_up running
    sim.drive(first, speed=0)
    events = Events(watcher, system.name)
    time.sleep(0.3)
    bridge = start_bridge(bridge_session, system, typemap, source=SOURCE)
    got = events.wait(lambda items: len({e.skillset for e in items}) == 2)
    spot = [e for e in got if e.skillset == "spot"]
    assert [view(e) for e in spot] == [
        (None, {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Busy"}, ["stand_up"], "initial status")]
    assert sim.terminate("spot", "stand_up", "success", "standing")
    events.wait(lambda items: len(items) >= 3)
    assert view(events.of("spot")[-1])[0] == "stand_up.success.standing" and events.of("spot")[-1].seq == 1
    bridge.close()
    sim.close()


def test_garbage_on_manager_keys_is_dropped(client_factory, spot_arm):
    system, typemap = spot_arm
    bridge_session, other, watcher = client_factory(), client_factory(), client_factory()
    events = Events(watcher, system.name)
    bridge = start_bridge(bridge_session, system, typemap, source=SOURCE, request_status=False)
    time.sleep(0.3)
    other.put("spot/spot_skillset_manager/spot_skillset/status", b"\x00\x01\x00\x00garbage")
    other.put("spot/spot_skillset_manager/spot_skillset/skill/teleop/response", b"")
    sim = Simulator(other, system, typemap)  # later messages are still handled
    time.sleep(0.3)
    bridge.request_status("spot")
    events.wait(lambda items: len(items) == 1)
    assert bridge.counters.malformed == 2
    bridge.close()
    sim.close()


# -- command line ---------------------------------------------------------------------------


def test_command_line_programs(router, client, spawn, watch, spot_arm, tmp_path: Path):
    """``python -m services.simulator`` and ``python -m services.bridge_ros2`` (live, then --replay)."""
    system, typemap = spot_arm
    zargs = ["--mode", "client", "--connect", router, "--no-multicast-scouting"]
    scenario = tmp_path / "chain.toml"
    scenario.write_text(CHAIN.replace('"spot_arm.toml"', f'"{REPO / "skillsets" / "spot_arm.toml"}"'))
    events = Events(client, system.name)
    recorder = Recorder(client, system)
    alive = watch(client, keys.alive(system.name, "bridge_ros2", "*"))
    bridge = spawn("services.bridge_ros2", str(REPO / "skillsets" / "spot_arm.toml"), "--instance", "cli", *zargs)
    alive.wait(lambda tokens: len(tokens) == 1, timeout=20)
    sim = spawn("services.simulator", str(scenario), "--speed", "0", "--start-delay", "2.5", "--linger", "0.2", *zargs)
    assert sim.wait(timeout=30) == 0
    got = events.wait(lambda items: len(items) >= EXPECTED_COUNT)
    for ss, expected in EXPECTED.items():
        assert [view(e) for e in got if e.skillset == ss] == expected
    assert {e.source for e in got} == {"bridge_ros2/cli"}
    bridge.terminate()
    assert bridge.wait(timeout=10) == 0
    bag = recorder.write(tmp_path / "cli_bag", StoragePlugin.MCAP, system, typemap)
    replay = spawn("services.bridge_ros2", str(REPO / "skillsets" / "spot_arm.toml"), "--replay", str(bag),
                   "--source", "replayed", *zargs)
    assert replay.wait(timeout=30) == 0
    replayed = events.wait(lambda items: sum(e.source == "replayed" for e in items) >= EXPECTED_COUNT, timeout=10)
    for ss, expected in EXPECTED.items():
        assert [view(e) for e in replayed if e.skillset == ss and e.source == "replayed"] == expected
