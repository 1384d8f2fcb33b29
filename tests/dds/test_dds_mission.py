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

from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from gateway import Gateway, free_domain
from native_build import native_binary
from services.chain import run_chain
from services.common.zenoh_config import session_config
from services.simulator.dds import DdsSimulator
from skinet.files import load_system, load_typemap, read_text
from skinet.mission import StepRecord, parse_scenario, replay
from skinet.ros.interfaces import status_request_topic
from skinet.ros.keys import KeyStyle

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
MISSIONS = REPO / "skillsets" / "missions"


@pytest.fixture(scope="module")
def plugin() -> Path:
    return native_binary("skinet-ros2dds-bridge")


@pytest.fixture(scope="module")
def unassisted() -> tuple:
    scenario = parse_scenario(read_text(MISSIONS / "unassisted.toml"), "unassisted")
    path = MISSIONS / scenario.system
    system, _ = load_system(path)
    return system, load_typemap(path), scenario


def comparable(records: list[StepRecord]) -> list[tuple]:
    return [(r.index, r.holds, r.violations, [(w.skillset, w.transition, w.property, w.constraint)
                                              for w in r.warnings], r.unsafe_count, r.divergence) for r in records]


@pytest.fixture
def gateway_factory(plugin: Path, tmp_path: Path) -> Iterator:
    gateways: list[Gateway] = []

    def start(**options) -> Gateway:
        gateways.append(Gateway(plugin, tmp_path, **options))
        return gateways[-1]

    yield start
    for g in gateways:
        g.close()
        print(f"--- zenoh-plugin-ros2dds (exit {g.proc.returncode}) ---\n{g.output()}")


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
    sim = DdsSimulator(session, system, typemap, domain=domain, distro=distro, style=style)
    try:
        records = run_chain(system, typemap, scenario, session=session, simulator=sim, style=style, settle=20)
        # The bridge's status_request crossed the plugin: the managers answered it (initial statuses).
        requests = {name: sim.handled(name, status_request_topic(node.component.skillset))
                    for name, node in sim.nodes.items()}
    finally:
        sim.close()
        session.close()
    assert all(n >= 1 for n in requests.values()), requests
    assert [(r.index, r.step.transition, r.violations) for r in records if r.violations] == [
        (26, "teleop.start", ["action_guard"]),
        (33, "go_to_waypoint.start", ["safety_guard"]),
        (38, "arm_ready.start", ["action_guard"]),
    ]
    assert comparable(records) == comparable(replay(system, scenario))
