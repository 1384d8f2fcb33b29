"""Pilot latency: from a marking change (a LiveState arriving) to the command sent (docs/semantics.md §8, issue 24).

The pilot drives the paper's mission (``skillsets/goals/paper_mission.toml``) lap after lap
on the paper's system.  A stand-in robot (the pilot's actuator here) answers each command at
once with its start and its favourable outcome as canonical events, as the bridge would
publish them (``tests/bridge_side.py``); the outcome's LiveState is the marking change after
which the pilot sends its next command.  A sample is the time from that LiveState's arrival
(a subscriber on the pilot's session) to the actuator's ``send``: the pilot's wait for the
step's prediction, the ``strict`` check's round trip and the plan (or its reuse) are in it.
The first lap (cold predictions, first plans) is left out, and so is each lap's first command (it
answers the goal request, not a marking change).

Rows:

- in-process: monitor, predictor, pilot and the stand-in robot on one peer session;
- through a router: the monitor and a predictor as processes (``python -m services.monitor``,
  ``python -m services.predictor``, client mode), the pilot and the robot in this process,
  clients of a loopback router.

Baselines measured in the same run: the check's own round trip (``get
skinet/<system>/check``, policy ``strict``) on each topology, the floor under the pilot's
latency; and, in-process on the mission's markings, a plan from scratch at every marking
change (a new :class:`~skinet.plan.Planner` each time) against the pilot's reuse of its plan
(``plan.action``).  Target: p99 <= 5 ms through the router.

    python benchmarks/bench_pilot.py [--laps 30]
"""

from __future__ import annotations

import argparse
import queue
import sys
import threading
import time
from pathlib import Path

from bench_check import get_once, row, timed, wait, wait_for_monitor
from common import table

import zenoh  # noqa: E402

from chains.chain import embedded_services  # noqa: E402
from services.pilot import start_pilot  # noqa: E402
from skinet.system.load import load_goals, load_system, load_typemap
from skinet.files.read import read_text
from skinet.pilot.flight import fly  # noqa: E402
from skinet.system.live import LiveSystem  # noqa: E402
from skinet.pilot.run import Outcomes  # noqa: E402
from skinet.plan import Planner  # noqa: E402
from skinet.system.model import System  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import decode, encode  # noqa: E402
from skinet.wire.messages import (  # noqa: E402
    CheckRequest, LiveState, PilotCommand, PilotGoalReply, PilotGoalRequest, PilotStatus, UnsafeReport,
)
from tests.bridge_side import BridgeSide  # noqa: E402
from tests.loopback import client_args, loopback_router  # noqa: E402
from tests.processes import start_module, stop_all  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SYSTEM_FILE = ROOT / "skillsets" / "spot_arm.toml"
GOALS_FILE = ROOT / "skillsets" / "goals" / "paper_mission.toml"
TARGET = 5e-3


class Robot:
    """The pilot's actuator: records each send, then plays the command's start and favourable outcome."""

    def __init__(self, side: BridgeSide, system: System):
        self.side, self.outcomes = side, Outcomes(system)
        self.sent: list[float] = []
        self._todo: queue.Queue[PilotCommand | None] = queue.Queue()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def send(self, command: PilotCommand) -> str:
        self.sent.append(time.perf_counter())
        self._todo.put(command)
        return "stand-in robot"

    def _run(self) -> None:
        while (c := self._todo.get()) is not None:
            skill = c.transition.partition(".")[0]
            self.side.send(c.skillset, c.transition)
            if c.transition.endswith(".start"):
                kind, mode = self.outcomes.outcome(c.skillset, skill)
                self.side.send(c.skillset, f"{skill}.{kind}.{mode}")

    def close(self) -> None:
        self._todo.put(None)
        self._thread.join(5)


class States:
    """When each LiveState step, and the UnsafeReport with its fresh prediction, first arrived (perf_counter),
    on the pilot's session."""

    def __init__(self, session: zenoh.Session, system: str):
        self.first: dict[int, float] = {}
        self.predicted: dict[int, float] = {}
        self._subs = [session.declare_subscriber(keys.state(system), self._on_state),
                      session.declare_subscriber(keys.unsafe(system), self._on_unsafe)]

    def _on_state(self, sample: zenoh.Sample) -> None:
        now = time.perf_counter()
        self.first.setdefault(decode(sample.payload.to_bytes(), LiveState).seq, now)

    def _on_unsafe(self, sample: zenoh.Sample) -> None:
        now = time.perf_counter()
        report = decode(sample.payload.to_bytes(), UnsafeReport)
        if not report.prediction_stale:
            self.predicted.setdefault(report.seq, now)

    def cause(self, t: float) -> tuple[float, float]:
        """The arrival of the last step that came before ``t``, and the time its prediction took to come."""
        seq, at = max(((s, a) for s, a in self.first.items() if a <= t), key=lambda x: x[1])
        return at, max(0.0, self.predicted.get(seq, at) - at)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def laps(session: zenoh.Session, system: System, side: BridgeSide, n: int) -> tuple[list[float], list[float]]:
    """Fly the mission ``n`` times with a pilot on ``session``; the latencies of laps 2..n, and the part of
    each spent waiting for the step's prediction."""
    robot = Robot(side, system)
    states = States(session, system.name)
    pilot = start_pilot(session, system, instance="bench", actuator=robot, typemap=load_typemap(SYSTEM_FILE))
    mission = read_text(GOALS_FILE)
    samples: list[float] = []
    waits: list[float] = []
    try:
        wait(lambda: pilot.status.state == "idle", "the pilot to follow the monitor")
        for lap in range(n):
            first = len(robot.sent)
            request = PilotGoalRequest(system=system.name, mission=mission, mode="drive")
            [reply] = [decode(r.ok.payload.to_bytes(), PilotGoalReply) for r in session.get(
                keys.pilot_goal(system.name, keys.LOCAL_CLIENT), payload=encode(request), timeout=10)
                if r.ok is not None]
            assert reply.accepted, reply.reason
            wait(lambda: _ended(pilot.status, reply.goal_id), f"lap {lap + 1} ({pilot.status.state})", 120)
            assert (pilot.status.state, pilot.status.denied) == ("reached", 0), pilot.status
            for t in robot.sent[first + 1:] if lap else ():  # a lap's first command answers the goal request
                at, wait_ = states.cause(t)
                samples.append(t - at)
                waits.append(wait_)
        return samples, waits
    finally:
        pilot.close()
        robot.close()
        states.close()


def _ended(status: PilotStatus, goal: int) -> bool:
    return status.goal_id == goal and status.state in ("reached", "failed", "cancelled")


def check_round_trip(session: zenoh.Session, system: str, n: int) -> list[float]:
    payload = encode(CheckRequest(skillset="spot", transition="teleop.start", policy="strict"))
    return timed(lambda: get_once(session, keys.check(system, keys.LOCAL_CLIENT), payload), n)


def in_process(n: int) -> list[list[object]]:
    system, _ = load_system(SYSTEM_FILE)
    # the pilot asks at machine speed here: no rate limit
    with embedded_services(None, system, True, check_rate_limit=0) as (session, _, _):
        side = BridgeSide(session, system.name, source="bench", model=system)
        try:
            side.synced()
            samples, waits = laps(session, system, side, n)
            return [row("in-process: LiveState -> command sent", samples, None),
                    row("  of which: the step's prediction coming (UnsafeReport)", waits, None),
                    row("baseline: the strict check's round trip, same session",
                        check_round_trip(session, system.name, 500), None)]
        finally:
            side.close()


def through_router(n: int) -> list[list[object]]:
    endpoint, router, (client, bridge) = loopback_router(2)
    zargs = [*client_args(endpoint), "--log-level", "ERROR"]
    procs = [start_module("services.predictor", *zargs, log=sys.stderr),
             start_module("services.monitor", str(SYSTEM_FILE), *zargs, "--check-rate-limit", "0", log=sys.stderr)]
    try:
        system, _ = load_system(SYSTEM_FILE)
        wait_for_monitor(client, system.name)
        side = BridgeSide(bridge, system.name, source="bench", model=system)
        side.synced()
        samples, waits = laps(client, system, side, n)
        rows = [row("router: LiveState -> command sent (monitor, predictor: processes)", samples, TARGET),
                row("  of which: the step's prediction coming (UnsafeReport)", waits, None),
                row("baseline: the strict check's round trip via the router",
                    check_round_trip(client, system.name, 500), None)]
        side.close()
        return rows
    finally:
        stop_all(procs, timeout=10)
        bridge.close()
        client.close()
        router.close()


def planning(system: System) -> list[list[object]]:
    """Plan from scratch at every marking change of one lap, against ``plan.action`` on the kept plan."""
    goals = load_goals(GOALS_FILE, system, load_typemap(SYSTEM_FILE))
    flight = fly(system, goals, Outcomes(system))
    live, visits, index = LiveSystem(system), [], 0
    for skillset, transition in flight.moves:  # (goal, marking) at every change
        live.apply(skillset, transition)
        if goals[index].target(skillset, transition):
            index = min(index + 1, len(goals) - 1)
        visits.append((goals[index], dict(live.marking)))
    kept = Planner(system)
    plans = [(kept.plan(goal, marking), marking) for goal, marking in visits]
    i = iter(range(1 << 30))

    def scratch() -> None:
        goal, marking = visits[next(i) % len(visits)]
        Planner(system).plan(goal, marking)

    def reuse() -> None:
        plan, marking = plans[next(i) % len(plans)]
        plan.action(marking)

    return [row("in-process: plan from scratch per change (new Planner)", timed(scratch, 300, 20), None),
            row("in-process: reuse the plan (plan.action)", timed(reuse, 3000, 100), None)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--laps", type=int, default=30, help="missions flown per topology, the first left out "
                                                              "(default: 30, about 28 commands each)")
    args = parser.parse_args()
    if args.laps < 2:
        parser.error("--laps must be at least 2 (the first lap is left out)")
    system, _ = load_system(SYSTEM_FILE)
    rows = in_process(args.laps) + through_router(args.laps) + planning(system)
    print(table(["path", "p50 µs", "p99 µs", "max µs", "target", "verdict"], rows))
    return 0 if all(r[-1] != "MISS" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
