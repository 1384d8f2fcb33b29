"""The whole chain on the embedded default (docs/mission.md acceptance, issue 5).

Simulated skillset managers -> ROS 2 encoding (CDR on bridge keys) -> bridge
-> monitor -> predictor, all on one Zenoh peer session in this process.  A
scenario is driven through the simulator and, after each step, the monitor's
published view is read back into the same :class:`~skinet.mission.scenario.StepRecord`
the core replay gives, so both can be printed and compared alike.

A step the model does not allow (``pick.success.picked`` while pick is idle) is a
model divergence there, as in the core replay (docs/semantics.md §7).  The simulated managers
refuse such a step as real ones would, so the monitor sees nothing happen; the
chain then judges the step itself on the marking the monitor published, with the
core's :class:`~skinet.system.live.LiveSystem`, and records the same divergence as the
core replay.  A step the model allows but the managers did not carry out is a
divergence too (the robot and its model disagree).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

import zenoh

from services.bridge_ros2 import start_bridge
from services.common.cli import default_instance_id
from services.common.zenoh_config import session_config
from services.monitor.service import MonitorView, Tap, start_monitor
from services.predictor.service import start_predictor
from services.simulator import Simulator
from services.simulator.driver import StepRun
from skinet.system.live import LiveSystem
from skinet.system.load import load_bindings, load_typemap
from skinet.mission.scenario import Scenario, StepRecord, flags_on
from skinet.ros.binding import Binding
from skinet.ros.keys import KeyStyle
from skinet.system.model import System
from skinet.verify.algorithm1 import UnsafeTransition
from skinet.wire.convert import marking_of
from skinet.wire.messages import UnsafeEntry


class ChainError(RuntimeError):
    """The chain did not settle in time (a service is stuck or lost messages)."""


_RUNS = itertools.count(1)


def run_instance() -> str:
    """An instance id of its own for each run's bridge (host-pid-n): runs one after the other in a process
    (``skinet demo`` on one session) must not share a liveliness token or an event source, or a monitor
    could take the previous bridge's leaving for its own bridge's."""
    return f"{default_instance_id()}-{next(_RUNS)}"


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
    after: Callable[[list[StepRecord]], None] | None = None,
    shared_predictor: bool = False,
    tap: Tap | None = None,
) -> list[StepRecord]:
    """Drive ``scenario`` through the whole chain and record what the monitor published.

    ``speed`` <= 0 plays as fast as the chain settles; ``settle`` bounds the
    wait for each step's effects (and, with ``predict``, for fresh predictions).
    By default everything shares one new peer session with simulated managers on
    Zenoh; a caller may give the ``session`` for the services (e.g. a client of a
    router, so that other processes can watch) and its own ``simulator`` (for
    instance managers on DDS behind a gateway whose keys are ``style``), which it
    then closes itself.  ``on_record`` is called after each step with what the
    monitor showed then, ``after`` with the records once the run is over, while
    every service still runs (``skinet demo --live`` keeps serving the views then).
    ``shared_predictor``: a predictor already serves ``session`` (:func:`shared_session`), start none.
    ``tap``: the monitor's (``--incidents``' ring, :meth:`services.monitor.incidents.Incidents.record`).
    """
    with embedded_services(session, system, predict and not shared_predictor, tap=tap) as (session, monitor, services):
        external = simulator is not None
        if simulator is None:
            simulator = Simulator(session, system, typemap)
            services.append(simulator)
        bridge = start_bridge(session, system, typemap, style=style, instance_id=run_instance())
        services.append(bridge)
        wait_until(monitor.synced, settle, "initial statuses")  # docs/semantics.md §7: every skillset live
        lost = statuses_lost(simulator, bridge) if external else {name: 0 for name in simulator.nodes}

        def caught_up(run: StepRun) -> None:
            expected = {name: n - lost[name] for name, n in simulator.statuses_published().items()}
            if not bridge.wait_statuses(expected):
                raise ChainError(f"step {run.index}: the bridge did not receive every status")
            seqs = lambda: {n: m.seq for n, m in bridge.feed.managers.items()}  # noqa: E731
            wait_until(lambda: handled_all(monitor, bridge.feed.source, seqs()), settle, f"step {run.index} applied")

        records, on_step = _recorder(system, monitor, caught_up, predict, settle, on_record)
        simulator.drive(scenario, speed=speed, on_step=on_step)
        if after is not None:
            after(records)
        return records


def run_bound_chain(
    system: System,
    bindings: Mapping[str, Binding],
    scenario: Scenario,
    *,
    predict: bool = True,
    speed: float = 0.0,
    settle: float = 10.0,
    session: zenoh.Session | None = None,
    style: KeyStyle = KeyStyle(),
    on_record: Callable[[StepRecord], None] | None = None,
    after: Callable[[list[StepRecord]], None] | None = None,
    then: Callable[[BoundChain], None] | None = None,
    shared_predictor: bool = False,
) -> list[StepRecord]:
    """:func:`run_chain` for a system whose skillsets are all bound to plain ROS 2 interfaces (docs/semantics.md §9).

    The simulated robot's action servers, lifecycle nodes and topics (CDR on Zenoh keys)
    -> the bound bridge -> monitor -> predictor.  After each step the chain waits until
    the bridge has fed every message the robot published on a bound topic (and fetched
    the results it needed), and the monitor has applied every event.  ``then`` is called
    after the last step, before ``after``, with the running chain (a pilot drives the
    robot from where the run left it: :mod:`chains.bound_pilot`).
    """
    from services.bridge_ros2.bound_live import start_bound_bridge
    from services.simulator.bound import BoundSimulator

    with embedded_services(session, system, predict and not shared_predictor) as (session, monitor, services):
        robot = BoundSimulator(session, system, bindings, style=style)
        services.append(robot)
        bridge = start_bound_bridge(session, system, bindings, style=style, settle=0.2, retry=0.2,
                                    instance_id=run_instance())
        services.append(bridge)
        robot.publish_topics(scenario.topics)
        wait_until(monitor.synced, settle, "initial statuses")  # docs/semantics.md §7: every skillset live
        watched = set(bridge.feed.routes)

        def caught_up() -> bool:
            published = sum(n for t, n in robot.published().items() if t in watched)
            return bridge.counters.messages >= published and not bridge.feed.pending_results()

        def step_done(run: StepRun) -> None:
            wait_until(caught_up, settle, f"step {run.index}: the bridge's messages")
            bridge.wait_idle(settle)
            seqs = lambda: {n: s.seq for n, s in bridge.feed.skillsets.items()}  # noqa: E731
            wait_until(lambda: handled_all(monitor, bridge.feed.source, seqs()), settle, f"step {run.index} applied")

        records, on_step = _recorder(system, monitor, step_done, predict, settle, on_record)
        robot.drive(scenario, speed=speed, on_step=on_step)
        if then is not None:
            then(BoundChain(session, system, bindings, style, robot, bridge, monitor))
        if after is not None:
            after(records)
        return records


def run_any_chain(system: System, system_file: Path, scenario: Scenario, *,
                  then: Callable[[BoundChain], None] | None = None, **options: Any) -> list[StepRecord]:
    """:func:`run_bound_chain` for a system whose skillsets are bound to plain ROS 2 interfaces (the bindings its
    file names), else :func:`run_chain` with the type map of ``system_file``: the chain a scenario file plays on.
    ``options`` are theirs, ``then`` the bound chain's only.  Cost: reading the bindings or the type map once."""
    if any(c.binding for c in system.components):
        return run_bound_chain(system, load_bindings(system)[0], scenario, then=then, **options)
    return run_chain(system, load_typemap(system_file), scenario, **options)


class BoundChain(NamedTuple):
    """The running parts of :func:`run_bound_chain`."""

    session: zenoh.Session
    system: System
    bindings: Mapping[str, Binding]
    style: KeyStyle
    robot: Any  # services.simulator.bound.BoundSimulator
    bridge: Any  # services.bridge_ros2.bound_live.BoundBridge
    monitor: Any  # services.monitor.service.Monitor


@contextmanager
def shared_session(predict: bool = True) -> Iterator[zenoh.Session]:
    """One peer session, with a predictor on it when ``predict``, for several runs in a row (``skinet demo``):
    each run brings its own monitor, simulator and bridge (``shared_predictor=True``), and the predictor's
    worker processes start once (about 1.5 s each time otherwise)."""
    session = zenoh.open(session_config("peer", multicast_scouting=False))
    predictor = start_predictor(session, "embedded") if predict else None
    try:
        yield session
    finally:
        if predictor is not None:
            predictor.close()
        session.close()


@contextmanager
def embedded_services(session: zenoh.Session | None, system: System, predict: bool,
                      **monitor_options: Any) -> Iterator[tuple[zenoh.Session, Any, list[Any]]]:
    """A session (a new peer one unless given), the monitor (``monitor_options``: :func:`start_monitor`'s) and a
    predictor on it, and the list of services to close at the end: the monitor first, then the others in reverse
    order (the session too, if it is ours).  Cost: the predictor's worker processes start (about 1.5 s)."""
    own = session is None
    if session is None:
        session = zenoh.open(session_config("peer", multicast_scouting=False))
    services: list[Any] = []
    try:
        monitor = start_monitor(session, system, **monitor_options)
        services.append(monitor)
        if predict:
            services.append(start_predictor(session, "embedded"))
        yield session, monitor, services
    finally:
        # The monitor first: it would report the bridge's leaving as a lost link on standard error.
        for service in [services[0], *reversed(services[1:])] if services else []:
            service.close()
        if own:
            session.close()


def _recorder(system: System, monitor: Any, caught_up: Callable[[StepRun], None], predict: bool, settle: float,
              on_record: Callable[[StepRecord], None] | None) -> tuple[list[StepRecord], Callable[[StepRun], None]]:
    """The records of a run and the step callback filling them: after ``caught_up(run)`` (the bridge has
    every message of the step and the monitor every event), what the monitor shows."""
    records: list[StepRecord] = []
    before = {p.name: True for p in system.properties}
    if predict:
        wait_until(lambda: not monitor.snapshot().unsafe.prediction_stale, settle, "initial prediction")
    first = monitor.snapshot()
    shown = [unsafe_transition(u) for u in first.unsafe.unsafe]  # what the operator sees
    seq = first.state.seq  # the monitor's last step

    def on_step(run: StepRun) -> None:
        nonlocal before, shown, seq
        caught_up(run)
        if predict:
            wait_until(lambda: not monitor.snapshot().unsafe.prediction_stale, settle, f"step {run.index} prediction")
        view = monitor.snapshot()
        stepped, seq = view.state.seq != seq, view.state.seq
        record = _record(run, view, before, shown, _divergence(system, run, view, stepped))
        if run.step.transition is not None:
            before = record.holds
            shown = [unsafe_transition(u) for u in view.unsafe.unsafe]
        records.append(record)
        if on_record is not None:
            on_record(record)

    return records, on_step


def statuses_lost(simulator: Simulator, bridge: Any) -> dict[str, int]:
    """Per skillset, the statuses of ``simulator`` that ``bridge`` will never see.  Behind a gateway,
    statuses answering the first requests are lost until its routes exist (volatile QoS); count them
    once the answers to the retries are in."""
    time.sleep(0.5)
    return {name: n - bridge.feed.statuses[name] for name, n in simulator.statuses_published().items()}


def handled_all(monitor: Any, source: str, next_seq: Mapping[str, int]) -> bool:
    """Whether the monitor handled every event ``source`` published (``next_seq``: per skillset, the seq
    its next event will have): applied, or covered by the resync it synced from."""
    for name, n in next_seq.items():
        last = monitor.last_seq(name, source)
        if n and (last is None or last < n - 1):
            return False
    return True


def unsafe_transition(u: UnsafeEntry) -> UnsafeTransition:
    return UnsafeTransition(u.skillset, u.transition, u.kind, u.controllable, u.property, u.constraint, u.steps,
                            tuple(u.witness), u.reason)


def _divergence(system: System, run: StepRun, view: MonitorView, stepped: bool) -> str | None:
    """Why the model could not explain ``run``'s step, if it could not.

    ``stepped``: the monitor published a step for it, whose divergence it reported
    itself.  Otherwise the robot did nothing the monitor could see: the step is
    applied to the published marking as the core replay applies it.
    """
    step = run.step
    if step.transition is None:
        return None
    if stepped:
        return view.state.divergence
    outcome = LiveSystem(system, marking_of(system, view.state.skillsets)).apply(step.skillset, step.transition)
    if outcome.divergence is not None or not outcome.changed:
        return outcome.divergence
    return (f"'{step.transition}' did not happen on the robot ({run.detail or 'no effect'}), "
            "though the model allows it here")


def _record(run: StepRun, view: MonitorView, before: dict[str, bool], shown: list[UnsafeTransition],
            divergence: str | None) -> StepRecord:
    holds = {v.name: v.holds for v in view.verdicts.properties}
    unsafe = view.unsafe.unsafe
    if run.step.consider is not None:
        warnings = flags_on(shown, run.step.skillset, run.step.consider)
        return StepRecord(run.index, run.step, dict(before), [], warnings, len(shown))
    violations = [p for p, ok in holds.items() if before.get(p, True) and not ok]
    recovery: dict[str, list[str]] = {p: [] for p in view.unsafe.violated}
    for r in view.unsafe.recovery:
        recovery.setdefault(r.property, []).append(f"{r.skillset}:{r.transition}")
    return StepRecord(run.index, run.step, holds, violations, [], len(unsafe), divergence,
                      flags_on(shown, run.step.skillset, run.step.transition or ""), recovery)


def wait_until(condition: Callable[[], object], timeout: float, what: str) -> None:
    """Poll ``condition`` until it holds; :class:`ChainError` naming ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise ChainError(f"timed out waiting for {what}")
        time.sleep(0.002)
