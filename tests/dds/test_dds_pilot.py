"""The pilot over real DDS and the real zenoh-plugin-ros2dds (issue 24, item 5; slow: cargo build).

A CycloneDDS participant in this process plays both skillset managers
(:class:`services.simulator.dds.DdsSimulator`), and their skills end by themselves
(:mod:`services.simulator.world`: the arm blocked once on its way to ready, one
not_arrived).  The plugin routes their topics to Zenoh; the bridge, the monitor, a
predictor and the pilot are clients of its router.  The pilot's requests are put on
Zenoh, cross the plugin and reach the managers as DDS samples (XCDR1), which the
managers decode; the skills run, the bridge reports the events, and the pilot reaches
every goal of the paper's mission, move for move as the core flies it.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh

from gateway import free_domain
from services.common.zenoh_config import session_config
from chains.pilot_chain import run_pilot_chain
from services.simulator.dds import DdsSimulator
from skinet.system.load import load_goals, load_system, load_typemap
from skinet.files.read import read_text
from skinet.pilot.flight import fly
from skinet.pilot.run import Outcomes, parse_pilot_run

pytestmark = pytest.mark.slow

MISSIONS = Path(__file__).resolve().parents[2] / "skillsets" / "missions"


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_the_pilot_drives_dds_managers_through_the_plugin(gateway_factory, distro: str):
    run = parse_pilot_run(read_text(MISSIONS / "pilot.toml"), "pilot.toml")
    system, _ = load_system(MISSIONS / run.system)
    typemap = load_typemap(MISSIONS / run.system)
    goals = load_goals(MISSIONS / run.goals, system, typemap)
    domain = free_domain()
    gateway = gateway_factory(domain=domain, distro=distro)
    session = zenoh.open(session_config("client", connect=[gateway.endpoint], multicast_scouting=False))
    sim = DdsSimulator(session, system, typemap, domain=domain, distro=distro)
    try:
        record = run_pilot_chain(system, typemap, run, read_text(MISSIONS / run.goals), duration=0.05,
                                 session=session, simulator=sim, settle=20)
        # Every request the pilot put on Zenoh was decoded by the DDS managers (CycloneDDS, then rosbags).
        decoded = sim.commands_handled()
    finally:
        sim.close()
        session.close()
    flight = fly(system, goals, Outcomes.of(run, system))
    assert [(e.skillset, e.transition) for e in record.events] == flight.moves
    assert (record.status.state, record.status.commands, record.status.denied) == ("reached", 34, 0)
    assert decoded == record.commands == 34
    assert record.violations == [] and record.retries == 2
    assert [(e.skill, e.kind, e.mode) for e in record.ends if e.kind == "failure"] == [
        ("arm_ready", "failure", "blocked"), ("go_to_waypoint", "failure", "not_arrived")]
