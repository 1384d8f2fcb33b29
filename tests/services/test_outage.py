"""Nothing lost across a router restart (issue 14; docs/semantics.md §7).

Canonical events go through the bridge's publisher (:func:`event_publisher`: a
cache and heartbeats) to the monitor's subscriber (:func:`event_subscriber`:
recovery from that cache).  The router is closed while events keep coming and
reopened on the same port: every event reaches the monitor in order.  With a
cache smaller than the outage, the monitor counts exactly the events it could not
get back and resyncs.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from services.bridge_ros2 import start_bridge
from services.common.events import event_subscriber
from services.common.zenoh_config import undeclare
from services.monitor import start_monitor
from services.simulator import Simulator
from skinet.mission.scenario import parse_scenario
from skinet.ros.keys import KeyStyle
from skinet.system.load import load_system
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import CanonicalEvent, LiveState
from tests.services.conftest import free_port, open_client, open_router
from tests.services.test_bridge import CHAIN
from tests.services.test_monitor import Events, wait_until

REPO = Path(__file__).resolve().parents[2]
SYSTEM = load_system(REPO / "skillsets" / "spot_arm.toml")[0]


class Outage:
    """A router on a fixed port that can be closed and reopened; ``login(user)`` opens a
    client session of it (users matter with access control)."""

    def __init__(self, router: Callable[[str], zenoh.Session] = open_router,
                 login: Callable[[str, str], zenoh.Session] = lambda endpoint, user: open_client(endpoint)) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self._open, self._login = router, login
        self.router: zenoh.Session | None = router(self.endpoint)

    def login(self, user: str) -> zenoh.Session:
        return self._login(self.endpoint, user)

    def down(self) -> None:
        assert self.router is not None
        self.router.close()
        self.router = None

    def up(self) -> None:
        self.router = self._open(self.endpoint)

    def close(self) -> None:
        if self.router is not None:
            self.router.close()


@pytest.fixture
def outage() -> Iterator[Outage]:
    o = Outage()
    yield o
    o.close()


def run(outage: Outage, cache: int, seconds: float, total: int = 200, rate: float = 40.0) -> tuple:
    """Publish ``total`` status events at ``rate``/s, with the router down ``seconds`` from the 40th."""
    pub_s, mon_s, obs_s = outage.login("bridge"), outage.login("monitor"), outage.login("observer")
    states: list[LiveState] = []
    # On the monitor's own session: what it publishes during the outage too.
    sub = mon_s.declare_subscriber(keys.state("spot_arm"), lambda s: states.append(
        decode(s.payload.to_bytes(), LiveState)))
    monitor = start_monitor(mon_s, SYSTEM)
    events = Events(pub_s, source="bridge", advanced=True, cache=cache, model=SYSTEM)
    try:
        events.synced()
        time.sleep(0.5)  # the monitor's subscription reaches the publisher
        down_at = 40
        up_at = down_at + int(seconds * rate)
        for n in range(total):
            if n == down_at:
                outage.down()
            if n == up_at:
                outage.up()
            events.send("spot", None)
            time.sleep(1 / rate)
        wait_until(lambda: monitor.counters.received + monitor.counters.unrecovered >= total, 20,
                   f"the events after recovery ({monitor.counters})")
        wait_until(monitor.synced, 10, "live again")
        time.sleep(1.0)  # anything late arrives now
        return monitor.counters, list(states)
    finally:
        events.close()
        monitor.close()
        sub.undeclare()
        for s in (pub_s, mon_s, obs_s):
            s.close()


def test_router_restart_loses_nothing(outage: Outage) -> None:
    counters, states = run(outage, cache=4096, seconds=3.0)
    assert (counters.received, counters.applied, counters.lost, counters.unrecovered, counters.out_of_order,
            counters.duplicates, counters.history) == (200, 200, 0, 0, 0, 0, 0)
    # The outage showed: the skillset was lost, then syncing, then live again (docs/semantics.md §7).
    seen = [s.sync["spot"].state for s in states]
    changes = [a for a, b in zip(seen, [None, *seen]) if a != b]
    assert changes == ["syncing", "live", "lost", "syncing", "live"], changes
    assert "the liveliness token of 'bridge' is gone" in next(s.sync["spot"].reason for s in states
                                                              if s.sync["spot"].state == "lost")


def test_outage_longer_than_the_cache_is_counted_exactly(outage: Outage) -> None:
    counters, _ = run(outage, cache=10, seconds=2.0)
    assert counters.unrecovered > 0
    assert counters.lost == counters.unrecovered == 200 - counters.applied
    assert counters.out_of_order == counters.duplicates == 0


@pytest.mark.parametrize("stamp", [0.0, -1.0, 4e9], ids=["1970", "wall-clock", "future"])
def test_a_late_monitor_does_not_replay_the_cache(outage: Outage, stamp: float) -> None:
    """zenoh.ext gives a new subscriber everything cached before the publisher's heartbeat: a monitor
    started late counts what its resync answer covers as history, whatever the events' stamps
    (here from 1970, now or 2096), and follows from the next event."""
    pub_s, mon_s = outage.login("bridge"), outage.login("monitor")
    events = Events(pub_s, source="bridge", advanced=True, model=SYSTEM, wait=False)
    stamp = time.time() if stamp < 0 else stamp
    try:
        for _ in range(50):
            events.send("spot", None, stamp=stamp)  # #1..#50, before the monitor starts
        monitor = start_monitor(mon_s, SYSTEM)
        try:
            events.synced()
            wait_until(lambda: monitor.counters.history == 50, 10, f"the cache's replay ({monitor.counters})")
            events.send("spot", "init_power.start", stamp=stamp)
            wait_until(lambda: monitor.counters.applied == 1, 5, "the live event")
            assert (monitor.counters.received, monitor.counters.lost) == (51, 0)
            assert monitor.snapshot().state.skillsets["spot"].running == ["init_power"]
        finally:
            monitor.close()
    finally:
        events.close()
        pub_s.close()
        mon_s.close()


# -- between the managers and the bridge (issue 25, item 8) ---------------------------------

CHAIN_STEPS = parse_scenario(CHAIN, "chain.toml")
FIRST_STEPS = dataclasses.replace(CHAIN_STEPS, steps=CHAIN_STEPS.steps[:3])  # init_power (start, success), stand_up
NEXT_STEP = dataclasses.replace(CHAIN_STEPS, steps=CHAIN_STEPS.steps[3:4])  # stand_up.success.standing


@pytest.mark.parametrize("style", [KeyStyle(), KeyStyle(rmw_zenoh=True, domain=8)], ids=["ros2dds", "rmw_zenoh"])
def test_router_restart_between_managers_and_bridge_is_resynced(outage: Outage, spot_arm: tuple,
                                                                 style: KeyStyle) -> None:
    """The router is down 3 s while Spot's manager runs three steps: their messages are lost (a
    manager's topics are volatile, nothing can recover them). The bridge notices its link was cut,
    asks every manager again once it is back, counts one resync per manager, and the next event of
    each skillset says so, with the status the manager really has; then events flow as before.
    With rmw_zenoh the managers' tokens leave and come back with the link: no restart is reported."""
    system, typemap = spot_arm
    sim_s, bridge_s, obs_s = outage.login("simulator"), outage.login("bridge"), outage.login("observer")
    got: list[CanonicalEvent] = []
    missed: list[int] = []
    sub, listener = event_subscriber(obs_s, keys.events(system.name, "*"), zenoh.handlers.Callback(
        lambda s: got.append(decode(s.payload.to_bytes(), CanonicalEvent))), missed.append)
    sim = Simulator(sim_s, system, typemap, style=style)
    time.sleep(0.3)
    bridge = start_bridge(bridge_s, system, typemap, style=style, source="bridge_ros2/test")
    try:
        wait_until(lambda: len(got) == 2, 5, "the initial statuses")
        outage.down()
        down = time.monotonic()
        assert [r.ok for r in sim.drive(FIRST_STEPS, speed=0)] == [True, True, True]
        time.sleep(max(0.0, 3.0 - (time.monotonic() - down)))
        outage.up()
        wait_until(lambda: {e.skillset for e in got if e.info.startswith("resync")} == {"spot", "manipulator"},
                   15, "a resync event per skillset")
        spot = [e for e in got if e.skillset == "spot"]
        arm = [e for e in got if e.skillset == "manipulator"]
        assert [e.seq for e in arm] == [0, 1]
        assert arm[1].info == "resync after the link to the managers was cut; same state as before"
        assert arm[1].status == arm[0].status
        assert spot[0].info == "initial status" and spot[-1].info.startswith(
            "resync after the link to the managers was cut; state now differs: power_status PowerOff -> PowerOn, "
            "control_mode Idle -> Busy, stand_up running")
        assert spot[-1].status is not None and (spot[-1].status.resources, spot[-1].status.running) == (
            {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Busy"}, ["stand_up"])
        assert (bridge.counters.resyncs, bridge.counters.restarts) == (2, 0)
        n = len(got)
        assert [r.ok for r in sim.drive(NEXT_STEP, speed=0)] == [True]
        wait_until(lambda: len(got) == n + 1, 5, "the next step")
        assert (got[-1].transition, got[-1].info, got[-1].seq) == ("stand_up.success.standing", "", spot[-1].seq + 1)
        assert missed == []
    finally:
        bridge.close()
        sim.close()
        undeclare(listener, sub)
        for s in (sim_s, bridge_s, obs_s):
            s.close()


def test_router_restart_between_a_bound_robot_and_the_bridge_is_read_again(outage: Outage) -> None:
    """The router is down 3 s while the Nav2 base's navigator is configured and its battery runs low: those
    messages are lost (lifecycle events and topics are volatile).  Once the link is back, the bridge says its
    status is not current (heartbeat ``pending``, resync refused) until it has read every interface again:
    the action statuses' caches, the node's state, the battery's next sample; then it publishes what changed
    and an event closing the gap."""
    from services.bridge_ros2.bound_live import start_bound_bridge
    from services.simulator.bound import BoundSimulator
    from skinet.system.load import load_bindings
    from tests.services.test_bound_bridge import FIRST, NAV2, _pending, _resync

    system = load_system(NAV2 / "nav2.toml")[0]
    bindings, _ = load_bindings(system)
    sim_s, bridge_s, obs_s = outage.login("simulator"), outage.login("bridge"), outage.login("observer")
    got: list[CanonicalEvent] = []  # an observer that recovers what its own reconnection missed, as a monitor
    sub, listener = event_subscriber(obs_s, keys.events(system.name, "*"), zenoh.handlers.Callback(
        lambda s: got.append(decode(s.payload.to_bytes(), CanonicalEvent))), lambda n: None)
    robot = BoundSimulator(sim_s, system, bindings)
    bridge = start_bound_bridge(bridge_s, system, bindings, settle=0.2, retry=0.2, source="bridge_ros2/b")
    try:
        deadline = time.monotonic() + 20
        while not got and time.monotonic() < deadline:  # periodic topics: again until the bridge subscribed
            robot.publish_topics(FIRST)
            time.sleep(0.5)
        wait_until(lambda: len(got) == 1, 5, "the initial status")
        outage.down()
        robot.lifecycle("nav2", "navigator", "Inactive")
        robot.publish("nav2", "/battery_state", {"percentage": 0.1, "power_supply_status": 1})
        time.sleep(3.0)
        outage.up()
        cut = "the link to the robot's interfaces was cut: waiting for a new /battery_state message"
        wait_until(lambda: _pending(obs_s, "nav2", 10) == {"nav2": cut}, 15, "the node and the servers read again")
        assert _resync(obs_s, "nav2", "nav2") == ("err", f"'bridge_ros2/b' has no current status of nav2: {cut}")
        wait_until(lambda: len(got) == 2, 5, "the navigator's event")
        assert [e.transition for e in got] == [None, "navigator_configured"]
        robot.publish("nav2", "/battery_state", {"percentage": 0.1, "power_supply_status": 1})
        wait_until(lambda: len(got) == 4, 5, "the battery's event and the end of the gap")
        assert [(e.transition, e.info) for e in got[2:]] == [
            ("battery_low", "/battery_state: percentage=0.10000000149011612 (battery Ok -> Low)"),
            (None, "resync after the link to the robot's interfaces was cut; state now differs: navigator "
                   "Unconfigured -> Inactive, battery Ok -> Low")]
        assert [e.seq for e in got] == [0, 1, 2, 3]
        assert _pending(obs_s, "nav2") == {} and bridge.counters.resyncs == 1
    finally:
        bridge.close()
        robot.close()
        undeclare(listener, sub)
        for s in (sim_s, bridge_s, obs_s):
            s.close()
