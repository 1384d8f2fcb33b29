"""bridge_ros2: simulated managers -> canonical events, live on Zenoh and from rosbag2 files.

Key mapping (skinet.ros.keys) first, then the simulator and the bridge on client
sessions of a loopback router, a recording of the managers' topics written as
sqlite3 and mcap bags and replayed, the start-up status request, and the two
command-line programs.
"""

from __future__ import annotations

import copy
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

from event_watch import Events
from services.bridge_ros2 import Feed, replay_bag, start_bridge
from services.bridge_ros2.record import BagRecorder, recorded_topics
from services.bridge_ros2.service import Bridge
from services.common.zenoh_config import session_config
from services.simulator import Simulator
from services.simulator.manager import Manager
from skinet.system.live import LiveSystem
from skinet.mission.scenario import parse_scenario
from skinet.ros.keys import (
    EMPTY_TYPE, KeyStyle, bridge_key, dds_type_name, manager_topics, node_entity, parse_liveliness_token,
    parse_rmw_attachment, rmw_attachment, rmw_zenoh_key, topic_entity, topic_fqn,
)
from skinet.ros.interfaces import generate_messages, package_name
from skinet.ros.typestore import build_typestore, default_instance
from skinet.ros.typestore import encode as cdr
from skinet.wire import keys
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


def run_chain(sessions: Callable[[], zenoh.Session], spot_arm, style: KeyStyle = KeyStyle(),
              bridge_style: KeyStyle | None = None, bag: Path | None = None, storage: str = "mcap") -> Events:
    """Simulator, bridge and a watcher on three sessions from ``sessions``; the CHAIN scenario played.  With
    ``bag``, the watcher also records the managers' topics there (``skinet rosbag``'s recorder, a ``ros2 bag
    record`` of the topics heard)."""
    system, typemap = spot_arm
    sim_session, bridge_session, watcher = sessions(), sessions(), sessions()
    events = Events(watcher, system.name)
    recorder = None if bag is None else BagRecorder(watcher, bag, recorded_topics(system, typemap, {}, style),
                                                    storage=storage, heard_only=True)
    sim = Simulator(sim_session, system, typemap, style=style)
    time.sleep(0.3)  # the watcher's subscriptions reach the router
    bridge = start_bridge(bridge_session, system, typemap, style=bridge_style or style, source=SOURCE)
    events.wait(lambda items: len(items) >= 2)  # each manager answered the bridge's status_request
    runs = sim.drive(parse_scenario(CHAIN, "chain.toml"), speed=0)
    assert [r.ok for r in runs] == [True, True, True, True, True, False, False, True, True, True, True, True,
                                    True, False], runs
    assert bridge.wait_statuses(sim.statuses_published())  # the bridge has caught up
    events.wait(lambda items: len(items) >= EXPECTED_COUNT)
    time.sleep(0.2)  # nothing more comes
    if recorder is not None:
        recorder.close()
    bridge.close()
    sim.close()
    return events


def recorded(bag: Path) -> list[tuple[str, bytes]]:
    """The messages of ``bag`` in their record order: (topic, CDR)."""
    with AnyReader([bag]) as reader:
        return [(conn.topic, bytes(raw)) for conn, _, raw in reader.messages()]


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
    events = run_chain(client_factory, spot_arm)
    check_chain(events, spot_arm)


def test_one_shared_peer_session(spot_arm):
    """Embedded: simulator, bridge and their listeners on a single session (docs/semantics.md §1, §7)."""
    session = zenoh.open(session_config("peer", multicast_scouting=False))
    try:
        events = run_chain(lambda: session, spot_arm)
        check_chain(events, spot_arm)
    finally:
        session.close()


def test_rmw_zenoh_chain(client_factory, spot_arm, tmp_path: Path):
    events = run_chain(client_factory, spot_arm, KeyStyle(rmw_zenoh=True, domain=1), bag=tmp_path / "bag")
    check_chain(events, spot_arm)
    samples = recorded(tmp_path / "bag")
    assert samples and all(fqn.startswith(("/spot/", "/kinova/")) for fqn, _ in samples)


def test_rmw_zenoh_humble_managers_with_a_bridge_expecting_type_hashes(client_factory, spot_arm):
    """Humble managers use TypeHashNotSupported keys (ros2/rmw_zenoh#388): the bridge takes the
    status_request key from their liveliness tokens, so its request reaches them anyway."""
    events = run_chain(client_factory, spot_arm, KeyStyle(rmw_zenoh=True, domain=2, humble=True),
                          bridge_style=KeyStyle(rmw_zenoh=True, domain=2))
    check_chain(events, spot_arm)


EMPTY = "std_msgs::msg::dds_::Empty_"
STATUS = "spot_skillset_interfaces::msg::dds_::SkillsetStatus_"


@pytest.mark.parametrize("humble", [True, False], ids=["humble", "jazzy"])
def test_rmw_zenoh_keys_and_tokens_of_both_distros(spot_arm, humble: bool):
    system, typemap = spot_arm
    comp = system.component("spot")
    store = build_typestore(comp.skillset, typemap)
    style = KeyStyle(rmw_zenoh=True, domain=5, humble=humble)
    request = next(t for t in manager_topics(comp.skillset) if t.kind == "status_request")
    hash_ = "TypeHashNotSupported" if humble else store.hash_rihs01("std_msgs/msg/Empty")
    assert style.key(comp.manager, request, store) == \
        f"5/spot/spot_skillset_manager/spot_skillset/status_request/{EMPTY}/{hash_}"
    node = node_entity(5, "a1b2c3", 3, "/spot/spot_skillset_manager")
    assert node.token() == "@ros2_lv/5/a1b2c3/3/3/NN/%/%spot/spot_skillset_manager"
    sub = topic_entity(node, 7, "MS", "/spot/spot_skillset_manager/spot_skillset/status_request", EMPTY_TYPE,
                       style.type_hash(store, EMPTY_TYPE))
    assert sub.token() == ("@ros2_lv/5/a1b2c3/3/7/MS/%/%spot/spot_skillset_manager/"
                           f"%spot%spot_skillset_manager%spot_skillset%status_request/{EMPTY}/{hash_}/::,:,:,:,,")
    assert parse_liveliness_token(sub.token()) == sub and parse_liveliness_token(node.token()) == node
    assert sub.node_fqn == "/spot/spot_skillset_manager"
    top = node_entity(0, "ff", 1, "/talker")
    assert top.token() == "@ros2_lv/0/ff/1/1/NN/%/%/talker" and parse_liveliness_token(top.token()).namespace == "/"
    for bad in ("@ros2_lv/0/ff/x/1/NN/%/%/talker", "@ros2_lv/0/ff/1/1/XX/%/%/talker", "0/chatter/a/b"):
        assert parse_liveliness_token(bad) is None


@pytest.mark.parametrize("humble", [True, False], ids=["humble", "jazzy"])
def test_the_bridge_and_the_managers_are_in_the_ros_graph(client_factory, watch, spot_arm, humble: bool):
    """Tokens as rmw_zenoh declares them: ``ros2 node list`` / ``ros2 topic info`` see the bridge."""
    system, typemap = spot_arm
    style = KeyStyle(rmw_zenoh=True, domain=4, humble=humble)
    graph = watch(client_factory(), "@ros2_lv/4/**")
    sim = Simulator(client_factory(), system, typemap, style=style)
    bridge = start_bridge(client_factory(), system, typemap, style=style, source=SOURCE, instance_id="lab-1")
    try:
        total = len(bridge.graph) + sum(len(node.tokens) for node in sim.nodes.values())
        alive = graph.wait(lambda a: len(a) == total)
        assert sum("/NN/" in k for k in alive) == 3
        entities = [parse_liveliness_token(k) for k in alive]
        assert sorted(e.node_fqn for e in entities if e.kind == "NN") == [
            "/kinova/manipulator_skillset_manager", "/skinet_bridge_lab_1", "/spot/spot_skillset_manager"]
        mine = [e for e in entities if e.node == "skinet_bridge_lab_1"]
        status = "/spot/spot_skillset_manager/spot_skillset/status"
        hash_ = "TypeHashNotSupported" if humble else \
            build_typestore(system.component("spot").skillset, typemap).hash_rihs01(
                "spot_skillset_interfaces/msg/SkillsetStatus")
        assert [(e.kind, e.dds_type, e.type_hash) for e in mine if e.topic == status] == [("MS", STATUS, hash_)]
        assert [e.kind for e in mine if e.topic.endswith("/status_request")] == ["MP", "MP"]
        assert {e.zid for e in mine} == {str(bridge.session.zid())} and len({e.entity_id for e in mine}) == len(mine)
        manager = [e for e in entities if e.node == "spot_skillset_manager" and e.topic == status]
        assert [(e.kind, e.type_hash) for e in manager] == [("MP", hash_)]
    finally:
        bridge.close()
        sim.close()
    graph.wait(lambda a: not any("skinet_bridge" in k for k in a))


@pytest.mark.parametrize("style", [KeyStyle(), KeyStyle(rmw_zenoh=True, domain=6)], ids=["ros2dds", "rmw_zenoh"])
def test_a_restarted_manager_is_asked_again_and_reported(client_factory, spot_arm, style: KeyStyle):
    """Mid-mission restart: the bridge notices it (rmw_zenoh: liveliness and the publisher's GID;
    any path: skill ids reset), asks for the status again, and the event says why."""
    system, typemap = spot_arm
    events = Events(client_factory(), system.name)
    sim = Simulator(client_factory(), system, typemap, style=style)
    time.sleep(0.3)
    bridge = start_bridge(client_factory(), system, typemap, style=style, source=SOURCE)
    try:
        events.wait(lambda items: len(items) == 2)
        sim.drive(parse_scenario(CHAIN, "chain.toml").__class__("c", "s", parse_scenario(CHAIN, "c").steps[:3]),
                  speed=0)
        events.wait(lambda items: len(items) == 5)  # spot: init_power.start, .success, stand_up.start
        sim.restart("spot")
        if not style.rmw_zenoh:  # no token tells the bridge: the next status gives it away (ids reset)
            assert sim.nodes["spot"].manager.skill_request("init_power", "again")  # the manager's own change
            bridge.request_status("spot")
        got = events.wait(lambda items: len(items) == 6)
        last = got[-1]
        assert (last.skillset, last.seq, last.transition, last.status.resources, last.status.running) == \
            ("spot", 4, None, {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Busy"} if not
             style.rmw_zenoh else {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"},
             ["init_power"] if not style.rmw_zenoh else [])
        why = "skill ids reset: stand_up" if not style.rmw_zenoh else "the manager (or its gateway) came back"
        diverged = "power_status PowerOn -> PowerOff, stand_up no longer running, init_power running" if not \
            style.rmw_zenoh else \
            "power_status PowerOn -> PowerOff, control_mode Busy -> Idle, stand_up no longer running"
        assert last.info == f"manager restarted ({why}); state now differs: {diverged}"
        assert last.restart and not any(e.restart for e in got[:-1])  # the monitor lists it (issue 27 item 4)
        assert bridge.counters.restarts == 1
    finally:
        bridge.close()
        sim.close()


def test_a_late_history_token_is_no_restart(client_factory, spot_arm, monkeypatch):
    """The managers' tokens, present before the bridge, reach it after their first statuses (a cold, loaded
    start: test_rmw_zenoh_chain failed so now and then): that is the first sight of each manager, not a
    comeback. A real restart is still reported."""
    system, typemap = spot_arm
    style = KeyStyle(rmw_zenoh=True, domain=9)
    gate = threading.Event()
    late = Bridge._on_token

    def after_the_first_statuses(self, sample):  # type: ignore[no-untyped-def]
        gate.wait(5.0)
        late(self, sample)

    monkeypatch.setattr(Bridge, "_on_token", after_the_first_statuses)
    events = Events(client_factory(), system.name)
    sim = Simulator(client_factory(), system, typemap, style=style)
    time.sleep(0.3)
    bridge = start_bridge(client_factory(), system, typemap, style=style, source=SOURCE)
    try:
        events.wait(lambda items: len(items) == 2)  # each manager's first status, asked for at start-up
        gate.set()
        time.sleep(0.5)  # the history tokens are handled; each asks for a status again
        assert sorted((e.skillset, e.info) for e in events.items) == [("manipulator", "initial status"),
                                                                       ("spot", "initial status")]
        assert bridge.counters.restarts == 0
        sim.restart("spot")  # the manager's own token leaves and comes back
        last = events.wait(lambda items: len(items) == 3)[-1]
        assert last.info == "manager restarted (the manager (or its gateway) came back); same state as before"
        assert last.restart
        assert bridge.counters.restarts == 1
    finally:
        bridge.close()
        sim.close()


@pytest.mark.parametrize("plugin", [StoragePlugin.SQLITE3, StoragePlugin.MCAP], ids=["sqlite3", "mcap"])
def test_rosbag_replay_equals_live(client_factory, spot_arm, tmp_path: Path, plugin: StoragePlugin):
    system, typemap = spot_arm
    bag = tmp_path / f"session_{plugin.name.lower()}"
    events = run_chain(client_factory, spot_arm, bag=bag, storage=plugin.name.lower())
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
    # In real time the replay takes as long as the recording of the topics it follows.
    watched = Feed(system, typemap, SOURCE).by_fqn()
    with AnyReader([bag]) as reader:
        stamps = [t for _, t, _ in reader.messages(connections=[c for c in reader.connections
                                                                if c.topic in watched])]
    span = (max(stamps) - min(stamps)) * 1e-9
    started = time.monotonic()
    again: list[CanonicalEvent] = []
    replay_bag(bag, system, typemap, again.append, source=SOURCE, realtime=True)
    assert time.monotonic() - started >= span * 0.9
    assert [e.model_copy(update={"epoch": 0}) for e in again] == [e.model_copy(update={"epoch": 0}) for e in replayed]


def overtaken(samples: list[tuple[str, str, bytes]], routes: dict) -> list[tuple[str, str, bytes]]:
    """``samples`` with every status moved before the responses of its skillset just before it."""
    out: list[tuple[str, str, bytes]] = []
    floor: dict[str, int] = {}  # a status never overtakes an earlier status's responses
    for sample in samples:
        ss, fqn, _ = sample
        i = len(out)
        if routes[fqn][1].kind == "status":
            while i > floor.get(ss, 0) and out[i - 1][0] == ss and \
                    routes[out[i - 1][1]][1].kind in ("skill_response", "event_response"):
                i -= 1
            floor[ss] = len(out) + 1
        out.insert(i, sample)
    return out


def test_statuses_that_overtake_their_responses(client_factory, spot_arm, tmp_path: Path):
    """Through a gateway each topic has its own route: a status may come before its responses."""
    system, typemap = spot_arm
    run_chain(client_factory, spot_arm, bag=tmp_path / "bag")
    routes = Feed(system, typemap, SOURCE).by_fqn()
    samples = [(routes[fqn][0], fqn, data) for fqn, data in recorded(tmp_path / "bag") if fqn in routes]
    swapped = overtaken(samples, routes)
    assert sum(a != b for a, b in zip(samples, swapped)) >= 10  # 7 responses overtaken, and their statuses

    def replay(order: list[tuple[str, str, bytes]], hold: float) -> tuple[list[CanonicalEvent], Feed]:
        feed = Feed(system, typemap, SOURCE, hold=hold)
        got = [ev for ss, fqn, data in order for ev in feed.feed(ss, routes[fqn][1], data)]
        return got + feed.flush(), feed

    got, feed = replay(swapped, hold=60.0)  # only the awaited response (or a newer status) releases one
    for ss, expected in EXPECTED.items():
        assert [view(e) for e in got if e.skillset == ss] == expected
    assert feed.counters.unexplained == 2  # the initial statuses
    # Without holding them, those statuses lose their transition names.
    unheld, feed = replay(swapped, hold=0.0)
    assert feed.counters.unexplained > 2 and [view(e) for e in unheld if e.skillset == "spot"] != EXPECTED["spot"]


def test_a_held_status_is_released_after_the_hold_time(spot_arm):
    """A response that never comes delays its status by ``hold`` seconds, no more."""
    system, typemap = spot_arm
    now = [0.0]
    feed = Feed(system, typemap, SOURCE, hold=0.5, clock=lambda: now[0])
    comp = system.component("spot")
    store = feed.managers["spot"].store
    manager = Manager(comp.skillset, store, info=comp.manager)
    topics = {t.topic: t for t in manager_topics(comp.skillset)}

    def put(messages) -> list[CanonicalEvent]:
        return [ev for m in messages if m.topic in {t.topic for t in feed.managers["spot"].topics}
                for ev in feed.feed("spot", topics[m.topic], cdr(store, m.typename, m.msg))]

    assert [e.info for e in put(manager.status_request())] == ["initial status"]
    assert [e.transition for e in put(manager.skill_request("init_power", "a", None))] == ["init_power.start"]
    out = manager.terminate("init_power", "success", "powered_on")
    response, status = out[-2], out[-1]
    assert put([status]) == [] and feed.deadline() == 0.5  # held: its response is missing
    now[0] = 0.4
    assert feed.expire() == []
    now[0] = 0.5
    late = feed.expire()
    assert [(e.transition, e.status.resources["power_status"]) for e in late] == [(None, "PowerOn")]
    assert feed.deadline() is None and put([response]) == []  # too late: a note only


def test_events_of_other_skillsets_wait_behind_a_held_status(spot_arm):
    """The monitor sees the robot's interleaving: a skillset's status waiting for its response keeps
    the other skillsets' later events behind it (the arm was ready before the legs started)."""
    system, typemap = spot_arm
    now = [0.0]
    feed = Feed(system, typemap, SOURCE, hold=0.5, clock=lambda: now[0])
    managers, topics = {}, {}
    for name in ("spot", "manipulator"):
        comp = system.component(name)
        managers[name] = Manager(comp.skillset, feed.managers[name].store, info=comp.manager)
        topics[name] = {t.topic: t for t in feed.managers[name].topics}

    def put(name: str, messages) -> list[tuple[str, str | None]]:
        store = feed.managers[name].store
        return [(ev.skillset, ev.transition) for m in messages if m.topic in topics[name]
                for ev in feed.feed(name, topics[name][m.topic], cdr(store, m.typename, m.msg))]

    assert put("spot", managers["spot"].status_request()) == [("spot", None)]
    assert put("manipulator", managers["manipulator"].status_request()) == [("manipulator", None)]
    assert put("manipulator", managers["manipulator"].skill_request("arm_ready", "a")) == \
        [("manipulator", "arm_ready.start")]
    *_, response, status = managers["manipulator"].terminate("arm_ready", "success", "ready")
    assert put("manipulator", [status]) == []  # overtook its response: held
    assert put("spot", managers["spot"].skill_request("init_power", "b")) == []  # came after: waits behind it
    assert feed.deadline() == 0.5
    assert put("manipulator", [response]) == [("manipulator", "arm_ready.success.ready"),
                                              ("spot", "init_power.start")]
    assert feed.deadline() is None
    # A response that never comes: the others wait the hold time, no more, and still come after it.
    assert put("manipulator", managers["manipulator"].skill_request("arm_joystick", "c")) == \
        [("manipulator", "arm_joystick.start")]
    *_, status = managers["manipulator"].terminate("arm_joystick", "success", "released")
    now[0] = 1.0
    assert put("manipulator", [status]) == []
    assert put("spot", managers["spot"].terminate("init_power", "success", "powered_on")) == []
    now[0] = 1.5
    assert [(e.skillset, e.transition) for e in feed.expire()] == [
        ("manipulator", None), ("spot", "init_power.success.powered_on")]


CYCLES = {  # (skill, outcome) played over and over by each manager; outcome None: an event
    "spot": [("init_power", "powered_on"), ("stand_up", "standing"), ("teleop", "done"), ("power_switchoff", None)],
    "manipulator": [("arm_ready", "ready"), ("arm_joystick", "released"), ("arm_moving_to_RD", "at_ready"),
                    ("arm_RD_to_HP", "at_home")],
}


def test_messages_of_two_managers_keep_their_arrival_order(client_factory, spot_arm):
    """Both managers publish in turn at full speed through a router: the bridge's events
    interleave as the messages did (a Python thread per subscription reordered about 3 % of them)."""
    system, typemap = spot_arm
    feed = Feed(system, typemap, SOURCE)  # the expected events, from the same messages in the same order
    streams: dict[str, list] = {}
    for name, cycle in CYCLES.items():
        comp = system.component(name)
        manager = Manager(comp.skillset, feed.managers[name].store, info=comp.manager)
        messages = manager.status_request()
        for i in range(120):
            skill, outcome = cycle[i % len(cycle)]
            messages += manager.raise_event(skill) if outcome is None else \
                manager.skill_request(skill, f"{name}-{i}") + manager.terminate(skill, "success", outcome)
        topics = {t.topic: t for t in feed.managers[name].topics}
        streams[name] = [(name, topics[m.topic], cdr(feed.managers[name].store, m.typename, m.msg))
                         for m in messages if m.topic in topics]
    interleaved = [m for pair in zip(*streams.values()) for m in pair]
    expected = [(ev.skillset, ev.seq) for ss, topic, data in interleaved for ev in feed.feed(ss, topic, data)]
    assert len(expected) > 400 and sum(a[0] != b[0] for a, b in zip(expected, expected[1:])) > 200

    publisher, watcher = client_factory(), client_factory()
    events = Events(watcher, system.name)
    bridge = start_bridge(client_factory(), system, typemap, source=SOURCE, request_status=False)
    pubs = {(ss, t.topic): publisher.declare_publisher(KeyStyle().key(system.component(ss).manager, t),
                                                       congestion_control=zenoh.CongestionControl.BLOCK)
            for ss, t, _ in interleaved}
    time.sleep(0.3)  # the bridge's subscriptions reach the router
    for ss, topic, data in interleaved:
        pubs[ss, topic.topic].put(data)
    got = events.wait(lambda items: len(items) >= len(expected), timeout=20)
    bridge.close()
    assert [(e.skillset, e.seq) for e in got] == expected


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


def test_rmw_zenoh_attachments_reveal_a_restarted_status_publisher(spot_arm):
    """A status from a new publisher GID, or with its sequence number going back, starts afresh."""
    system, typemap = spot_arm
    feed = Feed(system, typemap, SOURCE)
    comp = system.component("spot")
    store = feed.managers["spot"].store
    topic = next(t for t in feed.managers["spot"].topics if t.kind == "status")
    manager = Manager(comp.skillset, store, info=comp.manager)
    status = manager.status()
    payload = cdr(store, status.typename, status.msg)
    gid, other = bytes(range(16)), bytes(range(1, 17))
    infos = [[e.info for e in feed.feed("spot", topic, payload, rmw_attachment(seq, 0, g))]
             for seq, g in ((1, gid), (2, gid), (3, gid), (2, gid), (3, gid), (1, other))]
    assert infos == [
        ["initial status"], [], [],
        ["manager restarted (status sequence number went back); same state as before"], [],
        ["manager restarted (new status publisher); same state as before"]]
    assert feed.counters.restarts == 2


def test_a_bridge_started_before_the_managers_asks_them_when_they_appear(client_factory, spot_arm):
    """No retry needed: the managers' liveliness tokens tell the bridge when to ask (rmw_zenoh)."""
    system, typemap = spot_arm
    style = KeyStyle(rmw_zenoh=True, domain=7, humble=True)
    events = Events(client_factory(), system.name)
    bridge = start_bridge(client_factory(), system, typemap, style=style, source=SOURCE, retry=60.0, poll=60.0)
    time.sleep(1.0)  # the bridge's first requests went nowhere; its next retry is a minute away
    started = time.monotonic()
    sim = Simulator(client_factory(), system, typemap, style=style)
    try:
        got = events.wait(lambda items: len(items) == 2)
        assert time.monotonic() - started < 3.0
        assert sorted((e.skillset, e.info) for e in got) == [("manipulator", "initial status"),
                                                              ("spot", "initial status")]
        assert bridge.counters.restarts == 0
    finally:
        bridge.close()
        sim.close()


def status_of_another_version(skillset, typemap, drop: str, add: str) -> bytes:
    """CDR of the skillset's status as another version of its model would define it."""
    pkg = package_name(skillset)
    store, types = get_typestore(Stores.ROS2_HUMBLE), {}
    for name, text in generate_messages(skillset, typemap).items():
        if name == "SkillsetStatus":
            lines = [line for line in text.splitlines() if not drop or drop not in line]
            text = "\n".join(lines + ([f"{pkg}/{add}"] if add else []))
        types.update(get_types_from_msg(text, f"{pkg}/msg/{name}"))
    store.register(types)
    typename = f"{pkg}/msg/SkillsetStatus"
    return cdr(store, typename, default_instance(store, typename, info="/spot/spot_skillset_manager"))


def test_statuses_and_payloads_that_do_not_match_the_model(client_factory, spot_arm, caplog):
    """Counted every time, logged once per kind, never a crash; later statuses still handled."""
    system, typemap = spot_arm
    comp = system.component("spot")
    store = build_typestore(comp.skillset, typemap)
    manager = Manager(comp.skillset, store, info=comp.manager)
    status = manager.status()
    odd = copy.deepcopy(status.msg)
    odd.resources[0].state = "Levitating"
    odd.resources.append(odd.resources[1].__class__(name="battery", state="Low"))
    odd.skill_teleop.name = "fly"
    feed = Feed(system, typemap, SOURCE, hold=0)
    topic = next(t for t in feed.managers["spot"].topics if t.kind == "status")
    caplog.set_level(logging.WARNING, logger="skinet.bridge_ros2")
    good = cdr(store, status.typename, status.msg)
    assert [e.info for e in feed.feed("spot", topic, good)] == ["initial status"]
    for i in range(3):
        events = feed.feed("spot", topic, cdr(store, status.typename, odd))
        assert [(e.transition, e.status.resources["battery"]) for e in events] == ([(None, "Low")] if i == 0 else [])
    for drop, add in (("skill_teleop", ""), ("", "SkillTeleopStatus skill_fly")):  # older and newer versions
        for _ in range(2):
            assert feed.feed("spot", topic, status_of_another_version(comp.skillset, typemap, drop, add)) == []
    assert feed.counters.mismatched == 3 and feed.counters.malformed == 4
    warnings = [r.getMessage() for r in caplog.records]
    assert sum("state 'Levitating'" in w for w in warnings) == 1
    assert sum("'battery' is not in the model" in w for w in warnings) == 1
    assert sum("names skill 'fly', not 'teleop'" in w for w in warnings) == 1
    assert sum("malformed spot_skillset/status dropped (SerdeError" in w for w in warnings) == 1  # rosbags checks sizes
    assert [e.status.resources for e in feed.feed("spot", topic, good)] == [
        {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"}]  # back to normal


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
    bag = tmp_path / "cli_bag"
    recorder = BagRecorder(client, bag, recorded_topics(system, typemap, {}), heard_only=True)
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
    recorder.close()
    replay = spawn("services.bridge_ros2", str(REPO / "skillsets" / "spot_arm.toml"), "--replay", str(bag),
                   "--source", "replayed", *zargs)
    assert replay.wait(timeout=30) == 0
    replayed = events.wait(lambda items: sum(e.source == "replayed" for e in items) >= EXPECTED_COUNT, timeout=10)
    for ss, expected in EXPECTED.items():
        assert [view(e) for e in replayed if e.skillset == ss and e.source == "replayed"] == expected
