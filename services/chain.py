"""The whole chain on the embedded default (MISSION.md acceptance, issue 5).

Simulated skillset managers -> ROS 2 encoding (CDR on bridge keys) -> bridge
-> monitor -> predictor, all on one Zenoh peer session in this process.  A
scenario is driven through the simulator and, after each step, the monitor's
published view is read back into the same :class:`~skinet.mission.StepRecord`
the core replay gives, so both can be printed and compared alike.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping

import zenoh

from services.bridge_ros2 import start_bridge
from services.common.zenoh_config import session_config
from services.monitor.service import MonitorView, start_monitor
from services.predictor.service import start_predictor
from services.simulator import Simulator
from services.simulator.driver import StepRun
from skinet.mission import Scenario, StepRecord, flags_on
from skinet.ros.keys import KeyStyle
from skinet.system import System
from skinet.verify.algorithm1 import UnsafeTransition
from skinet.wire.messages import UnsafeEntry


class ChainError(RuntimeError):
    """The chain did not settle in time (a service is stuck or lost messages)."""


def run_chain(
    system: System,
    typemap: Mapping[str, str],
    scenario: Scenario,
    *,
    predict: bool = True,
    speed: float = 0.0,
    settle: float = 10.0,
    session: zenoh.Session | None = None,
    simulator: Simulator | None = None,
    style: KeyStyle = KeyStyle(),
    on_record: Callable[[StepRecord], None] | None = None,
) -> list[StepRecord]:
    """Drive ``scenario`` through the whole chain and record what the monitor published.

    ``speed`` <= 0 plays as fast as the chain settles; ``settle`` bounds the
    wait for each step's effects (and, with ``predict``, for fresh predictions).
    By default everything shares one new peer session with simulated managers on
    Zenoh; a caller may give the ``session`` for the services (e.g. a client of a
    router, so that other processes can watch) and its own ``simulator`` (for
    instance managers on DDS behind a gateway whose keys are ``style``), which it
    then closes itself.  ``on_record`` is called after each step with what the
    monitor showed then.
    """
    own = session is None
    if session is None:
        session = zenoh.open(session_config("peer", multicast_scouting=False))
    services: list = []
    try:
        monitor = start_monitor(session, system)
        services.append(monitor)
        if predict:
            services.append(start_predictor(session, "embedded"))
        external = simulator is not None
        if simulator is None:
            simulator = Simulator(session, system, typemap)
            services.append(simulator)
        bridge = start_bridge(session, system, typemap, style=style)
        services.append(bridge)
        _wait(monitor.synced, settle, "initial statuses")  # SPEC §7: every skillset live

        def caught_up() -> bool:  # the monitor handled every event the bridge published
            last = {name: monitor.last_seq(name, bridge.feed.source) for name in bridge.feed.managers}
            return all(m.seq == 0 or (last[name] is not None and last[name] >= m.seq - 1)
                       for name, m in bridge.feed.managers.items())

        lost = {name: 0 for name in simulator.nodes}
        if external:
            # Behind a gateway, statuses answering the first requests are lost until its
            # routes exist (volatile QoS); count them once the answers to the retries are in.
            time.sleep(0.5)
            lost = {name: n - bridge.feed.statuses[name] for name, n in simulator.statuses_published().items()}
        records: list[StepRecord] = []
        before = {p.name: True for p in system.properties}
        if predict:
            _wait(lambda: not monitor.snapshot().unsafe.prediction_stale, settle, "initial prediction")
        shown = [unsafe_transition(u) for u in monitor.snapshot().unsafe.unsafe]  # what the operator sees

        def on_step(run: StepRun) -> None:
            nonlocal before, shown
            expected = {name: n - lost[name] for name, n in simulator.statuses_published().items()}
            if not bridge.wait_statuses(expected):
                raise ChainError(f"step {run.index}: the bridge did not receive every status")
            _wait(caught_up, settle, f"step {run.index} applied")
            if predict:
                _wait(lambda: not monitor.snapshot().unsafe.prediction_stale, settle, f"step {run.index} prediction")
            view = monitor.snapshot()
            record = _record(run, view, before, shown)
            if run.step.transition is not None:
                before = record.holds
                shown = [unsafe_transition(u) for u in view.unsafe.unsafe]
            records.append(record)
            if on_record is not None:
                on_record(record)

        simulator.drive(scenario, speed=speed, on_step=on_step)
        return records
    finally:
        for service in reversed(services):
            service.close()
        if own:
            session.close()


def unsafe_transition(u: UnsafeEntry) -> UnsafeTransition:
    return UnsafeTransition(u.skillset, u.transition, u.kind, u.controllable, u.property, u.constraint, u.steps,
                            tuple(u.witness), u.reason)


def _record(run: StepRun, view: MonitorView, before: dict[str, bool], shown: list[UnsafeTransition]) -> StepRecord:
    holds = {v.name: v.holds for v in view.verdicts.properties}
    unsafe = view.unsafe.unsafe
    if run.step.consider is not None:
        warnings = flags_on(shown, run.step.skillset, run.step.consider)
        return StepRecord(run.index, run.step, dict(before), [], warnings, len(shown))
    violations = [p for p, ok in holds.items() if before.get(p, True) and not ok]
    recovery: dict[str, list[str]] = {p: [] for p in view.unsafe.violated}
    for r in view.unsafe.recovery:
        recovery.setdefault(r.property, []).append(f"{r.skillset}:{r.transition}")
    return StepRecord(run.index, run.step, holds, violations, [], len(unsafe), view.state.divergence,
                      flags_on(shown, run.step.skillset, run.step.transition or ""), recovery)


def _wait(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise ChainError(f"timed out waiting for {what}")
        time.sleep(0.002)
