"""Sequence numbers that cannot be poisoned (issue 14; docs/semantics.md §7 duplicated or out-of-order messages).

One forged event with the bridge's ``source`` and ``seq`` 2^64-1 used to make the
monitor drop the stream for good, as did a bridge restarted under the same source.
Now a stream is (skillset, source) within an epoch (one run of the bridge): a new
epoch, a wrap or a far jump starts the stream anew and asks the bridge for a status
resync, and at most ``max_streams`` streams are remembered.  The engine is tested
directly; the last test runs the real simulator, bridge and monitor on Zenoh.
"""

from __future__ import annotations

from pathlib import Path

from services.bridge_ros2 import start_bridge
from services.monitor import start_monitor
from services.monitor.engine import Engine
from services.simulator import Simulator
from skinet.system.load import load_system
from skinet.mission.scenario import parse_scenario
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import CanonicalEvent, LiveState, SkillsetStatus
from tests.services.test_bridge import CHAIN
from tests.services.test_monitor import wait_until

REPO = Path(__file__).resolve().parents[2]
SYSTEM = load_system(REPO / "skillsets" / "spot_arm.toml")[0]
BRIDGE = "bridge_ros2/robot"
TOP = 2**64 - 1


def ev(seq: int, transition: str | None = None, *, epoch: int = 7, source: str = BRIDGE,
       status: dict | None = None) -> CanonicalEvent:
    return CanonicalEvent(system="spot_arm", skillset="spot", seq=seq, stamp=0.0, source=source, epoch=epoch,
                          transition=transition, status=None if status is None else SkillsetStatus(**status))


def feed(engine: Engine, *events: CanonicalEvent) -> list[tuple[bool, bool]]:
    """(applied, resync asked) per event."""
    out = []
    for e in events:
        applied, _, resync = engine.check_seq(e)
        if applied:
            engine.apply(e)
        out.append((applied, resync))
    return out


def test_forged_top_seq_costs_one_resync_not_the_stream() -> None:
    engine = Engine(SYSTEM)
    got = feed(engine, ev(0, "init_power.start"), ev(TOP, "init_power.success.powered_on"),
               ev(1, "init_power.success.powered_on"), ev(2, "stand_up.start"))
    assert got == [(True, False), (True, True), (True, True), (True, False)]
    c = engine.counters
    assert (c.jumps, c.restarts, c.lost, c.duplicates, c.out_of_order) == (1, 1, 0, 0, 0)
    assert engine.last_seq[("spot", BRIDGE)] == (7, 2)


def test_wrapped_sequence_continues() -> None:
    engine = Engine(SYSTEM)
    got = feed(engine, ev(TOP - 1), ev(TOP), ev(0), ev(1), ev(1), ev(0))
    assert got == [(True, False), (True, False), (True, True), (True, False), (False, False), (False, False)]
    c = engine.counters
    assert (c.restarts, c.duplicates, c.out_of_order, c.lost) == (1, 1, 1, 0)


def test_restarted_bridge_opens_a_new_epoch() -> None:
    engine = Engine(SYSTEM)
    assert feed(engine, ev(0), ev(1), ev(2)) == [(True, False)] * 3
    # The same source restarted: its seq starts again at 0 in a new epoch.
    assert feed(engine, ev(0, epoch=8), ev(1, epoch=8)) == [(True, True), (True, False)]
    # A late event of the old run starts the stream anew as well (and is resynced), never blinds it.
    assert feed(engine, ev(3, epoch=7), ev(2, epoch=8)) == [(True, True), (True, True)]
    assert engine.counters.restarts == 3


def test_gap_is_counted_and_resynced() -> None:
    engine = Engine(SYSTEM)
    assert feed(engine, ev(0), ev(5), ev(4), ev(1000 + 5), ev(1000 + 6)) == [
        (True, False), (True, True), (False, False), (True, True), (True, False)]
    c = engine.counters
    assert (c.lost, c.out_of_order, c.jumps) == (4 + 999, 1, 0)
    assert feed(engine, ev(1006 + 1025)) == [(True, True)] and c.jumps == 1


def test_per_source_state_is_bounded() -> None:
    engine = Engine(SYSTEM, max_streams=256)
    for n in range(100_000):
        engine.check_seq(ev(0, source=f"forged-{n}"))
    assert len(engine.last_seq) == 256
    assert ("spot", "forged-99999") in engine.last_seq and ("spot", "forged-0") not in engine.last_seq
    engine.check_seq(CanonicalEvent(system="spot_arm", skillset="nope", seq=0, stamp=0.0, source="x"))
    assert ("nope", "x") not in engine.last_seq


def test_resync_answer_applies_only_when_newer() -> None:
    engine = Engine(SYSTEM)
    feed(engine, ev(0), ev(3))
    on = {"resources": {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Idle"}}
    assert not engine.resync(ev(2, status=on))  # older than what was applied
    assert engine.resync(ev(3, status=on))
    assert not engine.resync(ev(9))  # no status
    feed(engine, ev(TOP))  # forged: the bridge's own answer, far behind, wins
    assert engine.resync(ev(3, status=on)) and engine.last_seq[("spot", BRIDGE)] == (7, 3)


def test_forged_event_and_restarted_bridge_on_zenoh(client_factory, spot_arm, tmp_path) -> None:
    """Simulator -> bridge -> monitor: a forged top seq and a bridge restart under the same
    source leave the monitor following the robot, resynced from the bridge's status."""
    system, typemap = spot_arm
    sim_s, bridge_s, mon_s, attacker = client_factory(), client_factory(), client_factory(), client_factory()
    states: list[LiveState] = []
    sub = attacker.declare_subscriber(keys.state("spot_arm"), lambda s: states.append(
        decode(s.payload.to_bytes(), LiveState)))
    sim = Simulator(sim_s, system, typemap)
    monitor = start_monitor(mon_s, system)
    bridge = start_bridge(bridge_s, system, typemap, source=BRIDGE)
    chain = parse_scenario(CHAIN, "chain.toml")
    scenario = chain.__class__(chain.name, chain.system, chain.steps[:3])  # powered on, stand_up running
    try:
        wait_until(monitor.synced, 10, "the initial statuses")
        forged = ev(TOP, "init_power.start", epoch=bridge.feed.epoch)
        attacker.put(keys.events("spot_arm", "spot"), encode(forged))
        wait_until(lambda: monitor.counters.jumps == 1, 5, "the forged event")
        wait_until(lambda: monitor.counters.resyncs >= 1, 5, "the resync after the jump")
        sim.drive(scenario, speed=0)
        wait_until(lambda: states and states[-1].skillsets["spot"].running == ["stand_up"], 10,
                   "the monitor following the robot after the forged event")
        bridge.close()
        bridge = start_bridge(bridge_s, system, typemap, source=BRIDGE)  # same source, new epoch
        assert sim.terminate("spot", "stand_up", "success", "standing")
        wait_until(lambda: states[-1].skillsets["spot"].resources["posture"] == "Standing", 10,
                   "the monitor following the restarted bridge")
        # The bridge's resync answer took the stream back from the forged seq.  The restarted bridge
        # is a new run: its token went away (both skillsets lost), and both were resynced from the
        # new run before they counted as live again (docs/semantics.md §7).
        wait_until(monitor.synced, 5, "both skillsets live again")
        assert {n for st in states for n, x in st.sync.items() if x.state == "lost"} == {"spot", "manipulator"}
        assert (monitor.counters.jumps, monitor.counters.lost, monitor.counters.out_of_order) == (1, 0, 0)
        assert {monitor.snapshot().state.sync[n].source for n in ("spot", "manipulator")} == {BRIDGE}
    finally:
        sub.undeclare()
        bridge.close()
        monitor.close()
        sim.close()
