"""The paper's unassisted mission over real DDS and the real zenoh-plugin-ros2dds (slow: cargo build).

A CycloneDDS participant in this process plays both skillset managers
(:class:`services.simulator.dds.DdsSimulator`: the simulator's manager semantics, the
real ROS 2 topic names and types, XCDR1, ``ros_discovery_info`` as rmw publishes it);
the plugin, built from ``native/ros2dds_bridge``, routes their topics to Zenoh; our
bridge, monitor and predictor are clients of its router.  The operator's requests are
put on Zenoh and reach the managers through the plugin, so every step checks that
the DDS side decoded them.  Run with Humble and Jazzy discovery formats, and with a
namespace.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from event_watch import Events
from gateway import free_domain, free_port
from services.bridge_ros2 import start_bridge
from chains.chain import run_chain
from services.common.zenoh_config import session_config
from services.simulator.dds import DdsSimulator
from skinet.system.load import load_system, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import StepRecord, parse_scenario, replay
from skinet.ros.interfaces import status_request_topic
from skinet.ros.keys import KeyStyle, manager_topics
from skinet.ros.typestore import build_typestore, decode as decode_cdr, encode as cdr
from skinet.wire import keys

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
MISSIONS = REPO / "skillsets" / "missions"


@pytest.fixture(scope="module")
def unassisted() -> tuple:
    scenario = parse_scenario(read_text(MISSIONS / "unassisted.toml"), "unassisted")
    path = MISSIONS / scenario.system
    system, _ = load_system(path)
    return system, load_typemap(path), scenario


def comparable(records: list[StepRecord]) -> list[tuple]:
    return [(r.index, r.holds, r.violations, [(w.skillset, w.transition, w.property, w.constraint)
                                              for w in r.warnings], r.unsafe_count, r.divergence) for r in records]


def client(endpoint: str) -> zenoh.Session:
    return zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))


@pytest.mark.parametrize("distro,namespace", [("humble", ""), ("jazzy", ""), ("jazzy", "/robot1")],
                         ids=["humble", "jazzy", "jazzy-namespace"])
def test_unassisted_mission_through_dds_and_the_plugin(gateway_factory, unassisted, distro: str, namespace: str):
    system, typemap, scenario = unassisted
    domain = free_domain()
    gateway = gateway_factory(domain=domain, distro=distro, namespace=namespace or "/")
    style = KeyStyle(namespace=namespace)
    session = client(gateway.endpoint)
    status_key = style.key(system.component("spot").manager, next(
        t for t in manager_topics(system.component("spot").skillset) if t.kind == "status"))
    payloads: list[bytes] = []
    recorder = session.declare_subscriber(status_key, lambda s: payloads.append(s.payload.to_bytes()))
    sim = DdsSimulator(session, system, typemap, domain=domain, distro=distro, style=style)
    try:
        records = run_chain(system, typemap, scenario, session=session, simulator=sim, style=style, settle=20)
        # The bridge's status_request crossed the plugin: the managers answered it (initial statuses).
        requests = {name: sim.handled(name, status_request_topic(node.component.skillset))
                    for name, node in sim.nodes.items()}
        # Every operator request put on Zenoh was decoded by the DDS managers (CycloneDDS, then rosbags).
        decoded = sum(n for node in sim.nodes.values() for topic, n in node.handled.items()
                      if "/skill/" in topic or topic.endswith("event_request"))
    finally:
        recorder.undeclare()
        sim.close()
        session.close()
    # What the plugin puts on Zenoh is the DDS sample as is: XCDR1 little endian, rosbags' bytes plus padding.
    store = build_typestore(system.component("spot").skillset, typemap)
    typename = "spot_skillset_interfaces/msg/SkillsetStatus"
    assert len(payloads) >= 20
    for payload in payloads:
        ours = cdr(store, typename, decode_cdr(store, typename, payload))
        assert payload[:4] == b"\x00\x01\x00\x00" and payload[:len(ours)] == ours
        assert len(payload) - len(ours) in range(4) and not any(payload[len(ours):])
    assert all(n >= 1 for n in requests.values()), requests
    assert decoded == sum(1 for s in scenario.steps if s.transition and
                          (s.transition.endswith((".start", ".interrupt")) or "." not in s.transition))
    assert [(r.index, r.step.transition, r.violations) for r in records if r.violations] == [
        (26, "teleop.start", ["action_guard"]),
        (33, "go_to_waypoint.start", ["safety_guard"]),
        (38, "arm_ready.start", ["action_guard"]),
    ]
    assert comparable(records) == comparable(replay(system, scenario))


def test_bridge_started_before_the_plugin_gets_the_initial_statuses(gateway_factory, unassisted, tmp_path: Path):
    """The bridge (on a router of its own) and the DDS managers are up; the plugin comes last and links
    them: its route tokens tell the bridge to ask (its retry is a minute away), the statuses cross."""
    system, typemap, _ = unassisted
    domain = free_domain()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(session_config("router", listen=[endpoint], multicast_scouting=False))
    session = client(endpoint)
    events = Events(session, system.name)
    sim = DdsSimulator(session, system, typemap, domain=domain, distro="jazzy")
    bridge = start_bridge(session, system, typemap, source="bridge_ros2/dds", retry=60.0)
    try:
        time.sleep(1.5)  # the bridge's first requests went nowhere
        assert events.items == []
        started = time.monotonic()
        gateway_factory(domain=domain, distro="jazzy", connect=endpoint)
        got = events.wait(lambda items: len(items) == 2, timeout=20)
        assert time.monotonic() - started < 15
        assert sorted((e.skillset, e.transition, e.info) for e in got) == [
            ("manipulator", None, "initial status"), ("spot", None, "initial status")]
    finally:
        bridge.close()
        sim.close()
        session.close()
        router.close()


def test_a_dds_manager_restarting_mid_mission(gateway_factory, unassisted):
    """The DDS participant goes and a new one comes (the robot's managers restarted): the plugin
    retires and re-creates its routes, the bridge asks the new managers and reports the divergence."""
    system, typemap, scenario = unassisted
    domain = free_domain()
    gateway = gateway_factory(domain=domain, distro="jazzy")
    session = client(gateway.endpoint)
    events = Events(session, system.name)
    sim = DdsSimulator(session, system, typemap, domain=domain, distro="jazzy")
    bridge = start_bridge(session, system, typemap, source="bridge_ros2/dds")
    try:
        events.wait(lambda items: len(items) == 2, timeout=20)
        first = scenario.__class__(scenario.name, scenario.system, scenario.steps[:2])  # spot powered on
        assert all(run.ok for run in sim.drive(first, speed=0))
        events.wait(lambda items: len(items) == 4)
        sim.close()
        sim = DdsSimulator(session, system, typemap, domain=domain, distro="jazzy")
        got = events.wait(lambda items: len(items) == 6, timeout=20)
    finally:
        bridge.close()
        sim.close()
        session.close()
    spot = [e for e in got[4:] if e.skillset == "spot"]
    assert [(e.seq, e.transition, e.info) for e in spot] == [
        (3, None, "manager restarted (the manager (or its gateway) came back); state now differs: "
                  "power_status PowerOn -> PowerOff")]
    assert bridge.counters.restarts == 2  # both managers came back (one participant)


def test_command_line_simulator_on_dds_behind_the_plugin(gateway_factory, unassisted, tmp_path: Path):
    """``python -m services.simulator --dds`` and ``python -m services.bridge_ros2`` as separate processes."""
    system, typemap, scenario = unassisted
    domain = free_domain()
    gateway = gateway_factory(domain=domain, distro="humble", namespace="/lab")
    zargs = ["--mode", "client", "--connect", gateway.endpoint, "--no-multicast-scouting"]
    session = client(gateway.endpoint)
    events = Events(session, system.name)
    logs = {name: (tmp_path / f"{name}.log").open("w+") for name in ("bridge", "simulator")}
    bridge = subprocess.Popen([sys.executable, "-m", "services.bridge_ros2", str(REPO / "skillsets" / "spot_arm.toml"),
                               "--namespace", "/lab", "--instance", "cli", *zargs],
                              cwd=REPO, stdout=logs["bridge"], stderr=subprocess.STDOUT)
    try:
        # The simulator plays once the bridge listens (its token): a loaded machine started it too late for a
        # fixed delay once, and it missed the first steps.
        token = keys.alive(system.name, "bridge_ros2", "cli")
        deadline = time.monotonic() + 60
        while not any(r.ok is not None for r in session.liveliness().get(token, timeout=1.0)):
            assert time.monotonic() < deadline and bridge.poll() is None, "the bridge never declared its token"
            time.sleep(0.1)
        sim = subprocess.run([sys.executable, "-m", "services.simulator", str(MISSIONS / "unassisted.toml"), "--dds",
                              "--domain", str(domain), "--ros-distro", "humble", "--namespace", "/lab",
                              "--speed", "0", "--start-delay", "3", "--linger", "1", *zargs],
                             cwd=REPO, capture_output=True, text=True, timeout=120)
        assert sim.returncode == 0, sim.stdout + sim.stderr
        steps = [line for line in sim.stdout.splitlines() if line.startswith("step ")]
        assert len(steps) == len(scenario.steps)
        played = [(s.skillset, s.transition) for s, line in zip(scenario.steps, steps)
                  if s.transition and not line.endswith("(no effect)")]
        got = events.wait(lambda items: sum(e.transition is not None for e in items) >= len(played), timeout=20)
        for name in ("spot", "manipulator"):
            assert [e.transition for e in got if e.skillset == name and e.transition] == \
                [t for ss, t in played if ss == name]
        assert {e.source for e in got} == {"bridge_ros2/cli"}
    finally:
        bridge.terminate()
        bridge.wait(10)
        session.close()
        for name, log in logs.items():
            log.seek(0)
            print(f"--- {name} ---\n{log.read()}")
            log.close()
