"""A pilot run through the whole chain (issue 24, the demo's third run; docs/semantics.md §8, *The pilot*).

Simulated skillset managers whose skills end by themselves (:mod:`services.simulator.world`,
with the failures a pilot run declares) -> ROS 2 encoding (CDR) -> bridge -> monitor ->
predictor -> pilot -> the monitor's check -> the pilot's requests on the managers' topics,
all on one Zenoh session (a new peer one, or the caller's).  The run's goals file is sent
to the pilot's goal queryable as a mission, in the run's mode, as ``skinet goal`` sends it;
the run ends when the pilot's status says the mission ended (reached, failed, cancelled),
once the world has ended every skill it started and the monitor has applied every event.

What it gives back is measured on the robot's side of the chain, not taken from the
pilot's word: the commands the managers handled, the transitions the bridge reported (in
the monitor's order), the properties the monitor's own verdicts showed violated; and the
pilot's statuses beside them (its ``commands`` and ``denied``).  The transitions also make
a :class:`~skinet.mission.scenario.Scenario` (one step per transition), which
:func:`skinet.mission.scenario.replay` turns into the records ``skinet demo`` prints and logs.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import zenoh

from services.bridge_ros2 import start_bridge
from chains.chain import ChainError, embedded_services, handled_all, run_instance, statuses_lost, wait_until
from services.common.goals import ask_pilot
from services.pilot import start_pilot
from services.pilot.act import ManagerActuator
from services.simulator import Simulator
from services.simulator.world import End, World
from skinet.mission.scenario import Scenario, Step
from skinet.pilot.run import Outcomes, PilotRun
from skinet.errors import SkinetError
from skinet.ros.keys import KeyStyle
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import CanonicalEvent, PilotGoalReply, PilotGoalRequest, PilotStatus, Verdicts

ENDED = ("reached", "failed", "cancelled")


@dataclass
class PilotRecord:
    """A pilot run as the chain saw it."""

    run: PilotRun
    reply: PilotGoalReply  # the pilot's answer to the mission
    status: PilotStatus  # its last status
    states: list[str] = field(default_factory=list)  # the pilot's states in order, repeats folded
    events: list[CanonicalEvent] = field(default_factory=list)  # the transitions the bridge reported
    violations: list[tuple[str, int]] = field(default_factory=list)  # (property, Verdicts.seq) turned false
    commands: int = 0  # skill requests and interrupts the managers handled
    ends: list[End] = field(default_factory=list)  # the executions the simulated implementations ended
    seconds: float = 0.0  # from the mission sent to its end

    @property
    def retries(self) -> int:
        """Failed skill runs the pilot had to get past (each failure outcome the monitor saw)."""
        return sum((e.transition or "").split(".")[1:2] == ["failure"] for e in self.events)

    def scenario(self, system_path: str = "") -> Scenario:
        """The run as a scenario: one step per transition, at its time from the first one."""
        first = self.events[0].stamp if self.events else 0.0
        steps = tuple(Step(max(0.0, e.stamp - first), e.skillset, e.transition) for e in self.events)
        return Scenario(self.run.name, system_path or self.run.system, steps)


def run_pilot_chain(
    system: System,
    typemap: Mapping[str, str],
    run: PilotRun,
    mission: str,
    *,
    mission_name: str = "goals.toml",
    duration: float = 0.0,
    timeout: float = 120.0,
    settle: float = 10.0,
    session: zenoh.Session | None = None,
    simulator: Simulator | None = None,
    style: KeyStyle = KeyStyle(),
    shared_predictor: bool = False,
    on_status: Callable[[PilotStatus], None] | None = None,
    then: Callable[[PilotRecord], None] | None = None,
) -> PilotRecord:
    """Send ``mission`` (a goals file's text) to a pilot on the whole chain and follow it to its end.

    ``duration``: seconds each simulated skill runs; ``timeout``: seconds the whole mission may
    take; ``settle`` bounds the start-up and the final catching up.  By default everything shares
    one new peer session with simulated managers on Zenoh; a caller may give the ``session`` and
    its own ``simulator`` (managers on DDS behind a gateway, or with ``rmw_zenoh`` keys: ``style``),
    which it then closes itself; ``shared_predictor``: a predictor already serves ``session`` (else one is
    started: the pilot sends a command only from a step whose prediction came, so there is always one);
    ``on_status``: called with each of the pilot's statuses as it comes (on Zenoh's thread: must not block);
    ``then``: called with the record while every service still runs (a live demo's views keep its pilot).
    Raises :class:`~chains.chain.ChainError` when the pilot refuses the mission or the chain does not
    settle.
    """
    with embedded_services(session, system, not shared_predictor) as (session, monitor, services):
        external = simulator is not None
        if simulator is None:
            simulator = Simulator(session, system, typemap, style=style)
            services.append(simulator)
        world = World(simulator, Outcomes.of(run, system), duration)
        services.append(world)
        instance = run_instance()
        bridge = start_bridge(session, system, typemap, style=style, instance_id=instance)
        services.append(bridge)
        watch = _Watch(session, system.name, on_status)
        services.append(watch)
        actuator = ManagerActuator(session, system, typemap, style=style, instance=f"pilot-{instance}")
        pilot = start_pilot(session, system, instance=instance, actuator=actuator, typemap=typemap)
        services.append(pilot)
        wait_until(monitor.synced, settle, "initial statuses")  # docs/semantics.md §7: every skillset live
        lost = statuses_lost(simulator, bridge) if external else {name: 0 for name in simulator.nodes}
        wait_until(lambda: pilot.status.state == "idle", settle, "the pilot to follow the monitor")
        request = PilotGoalRequest(system=system.name, mission=mission, mission_name=mission_name, mode=run.mode)
        started = time.monotonic()
        reply = ask_goal(session, request, settle)
        if not reply.accepted:
            raise ChainError(f"the pilot refused the mission: {reply.reason}")
        try:
            wait_until(lambda: watch.ended(reply.goal_id), timeout, "the end of the mission")
        except ChainError:
            status = pilot.status
            raise ChainError(f"the pilot's mission did not end within {timeout:g} s: it is {status.state}"
                             + (f" ({status.reason})" if status.reason else "")
                             + f" at goal {status.index + 1} of {len(status.goals)}") from None
        seconds = time.monotonic() - started
        wait_until(world.idle, settle, "the simulated skills' ends")
        expected = {name: n - lost[name] for name, n in simulator.statuses_published().items()}
        if not bridge.wait_statuses(expected, settle):
            raise ChainError("the bridge did not receive every status")
        seqs = lambda: {n: m.seq for n, m in bridge.feed.managers.items()}  # noqa: E731
        wait_until(lambda: handled_all(monitor, bridge.feed.source, seqs()), settle, "the last events applied")
        wait_until(lambda: watch.caught_up(monitor.snapshot().verdicts.seq, seqs()), settle,
                   "the last verdicts and events")
        record = watch.record(run, reply, pilot.status, simulator.commands_handled(), list(world.ends), seconds)
        if then is not None:
            then(record)
        return record


def ask_goal(session: zenoh.Session, request: PilotGoalRequest, timeout: float) -> PilotGoalReply:
    """The in-process pilot's reply to ``request`` (:func:`~services.common.goals.ask_pilot` under the local
    login); :class:`ChainError` when none comes within ``timeout`` or it does not decode."""
    try:
        return ask_pilot(session, request, keys.LOCAL_CLIENT, timeout)
    except SkinetError as exc:
        raise ChainError(str(exc)) from None


class _Watch:
    """The events, verdicts and pilot statuses of one system, as they are published."""

    def __init__(self, session: zenoh.Session, system: str, on_status: Callable[[PilotStatus], None] | None = None):
        self._on_status = on_status
        self._cond = threading.Condition()
        self.events: list[CanonicalEvent] = []
        self.violations: list[tuple[str, int]] = []
        self.statuses: list[PilotStatus] = []
        self._holds: dict[str, bool] = {}
        self._verdicts = -1
        self._seqs: dict[str, int] = {}  # skillset -> the last seq of its events seen here
        self._subs = [
            session.declare_subscriber(keys.events(system, "*"), lambda s: self._take(s, CanonicalEvent)),
            session.declare_subscriber(keys.verdicts(system), lambda s: self._take(s, Verdicts)),
            session.declare_subscriber(keys.pilot_status(system), lambda s: self._take(s, PilotStatus)),
        ]

    def _take(self, sample: zenoh.Sample, kind: type) -> None:
        message = decode(sample.payload.to_bytes(), kind)
        with self._cond:
            if isinstance(message, CanonicalEvent):
                self._seqs[message.skillset] = max(self._seqs.get(message.skillset, -1), message.seq)
                if message.transition is not None:
                    self.events.append(message)
            elif isinstance(message, Verdicts):
                self._verdicts = max(self._verdicts, message.seq)
                for v in message.properties:
                    if not v.holds and self._holds.get(v.name, True):
                        self.violations.append((v.name, message.seq))
                    self._holds[v.name] = v.holds
            else:
                self.statuses.append(message)
                if self._on_status is not None:
                    self._on_status(message)
            self._cond.notify_all()

    def ended(self, goal_id: int) -> bool:
        with self._cond:
            return any(s.goal_id == goal_id and s.state in ENDED for s in self.statuses)

    def caught_up(self, verdicts_seq: int, next_seq: Mapping[str, int]) -> bool:
        """Whether the verdicts up to ``verdicts_seq`` and every event before ``next_seq`` (skillset -> the seq
        of its next event, as in :func:`~chains.chain.handled_all`) came here: the monitor's subscription
        may see the last events before this one does."""
        with self._cond:
            return self._verdicts >= verdicts_seq and all(self._seqs.get(n, -1) >= q - 1 for n, q in next_seq.items())

    def record(self, run: PilotRun, reply: PilotGoalReply, status: PilotStatus, commands: int, ends: list[End],
               seconds: float) -> PilotRecord:
        with self._cond:
            states = [s.state for s in sorted(self.statuses, key=lambda s: s.seq)]
            folded = [s for i, s in enumerate(states) if i == 0 or s != states[i - 1]]
            return PilotRecord(run, reply, status, folded, list(self.events), list(self.violations), commands, ends,
                               seconds)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


__all__ = ["PilotRecord", "ask_goal", "run_pilot_chain"]
