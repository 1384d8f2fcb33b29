"""``skinet demo``'s pilot run and the table of every run side by side (issue 24, the demo).

A pilot run file (:mod:`skinet.pilot.run`, ``skillsets/missions/pilot.toml``) hands a goals
file to the pilot, which drives the simulated managers through the whole chain
(:func:`chains.pilot_chain.run_pilot_chain`), or, with ``--core``, the pilot's drive mode
on the core (:func:`skinet.pilot.flight.fly`).  Either way the moves become a scenario that the
core replays (:func:`skinet.mission.scenario.replay`), so that its notable steps, ``--log`` and
``--timeline`` read as the other runs'.  The table at the end counts, per run: the commands
sent (skill starts and interrupts), the moves (every transition: commands, outcomes,
events), the retries (failed skill runs the pilot got past; none in an operator's run
without failures), the violations, and for a pilot run the commands the check denied.
"""

from __future__ import annotations

import argparse
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from skinet.system.load import load_goals, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import Scenario, Step, StepRecord, replay
from skinet.pilot.run import Outcomes, PilotRun, check_pilot_run, parse_pilot_run
from skinet.plan import Goal
from skinet.system.model import System
from services.common.options import load_live_system, require_properties

if TYPE_CHECKING:
    import zenoh

    from chains.pilot_chain import PilotRecord
    from skinet.wire.messages import PilotStatus

# What a pilot run played to: its scenario, records, table row (None when the chain did not let it end),
# surprises
PlayedPilot = tuple[Scenario, list[StepRecord], "Row | None", list[str]]
SKILL_SECONDS = 0.05  # how long each simulated skill runs: the pilot's commands stay under the check's rate limit
LIVE_SKILL_SECONDS = 2.0  # the same with --live, at speed 1


@dataclass
class PilotEntry:
    """A pilot run file, checked and ready to play."""

    path: Path
    run: PilotRun
    system: System
    goals: list[Goal]
    mission: str  # the goals file's text, as the pilot gets it
    goals_path: Path


@dataclass
class Row:
    """One run in the table."""

    name: str
    commands: int
    moves: int
    retries: int
    violations: int
    denied: int | None = None  # a pilot run's


def load_pilot_entry(path: Path, text: str, no_properties: bool) -> PilotEntry:
    """Parse and check a pilot run file and its goals file (one-line errors with their positions)."""
    run = parse_pilot_run(text, str(path))
    system_path = path.parent / run.system
    system, _ = load_live_system(system_path)
    require_properties(system, system_path, no_properties)
    check_pilot_run(run, system, str(path))
    goals_path = Path(os.path.normpath(path.parent / run.goals))
    goals = load_goals(goals_path, system, load_typemap(system_path))
    return PilotEntry(path, run, system, goals, read_text(goals_path), goals_path)


def play_pilot(args: argparse.Namespace, entry: PilotEntry, line: Callable[[StepRecord], str],
               session: zenoh.Session | None = None, live: bool = False,
               then: Callable[[PlayedPilot], None] | None = None) -> PlayedPilot:
    """Fly the pilot run (through the chain on ``session``, where a predictor runs unless ``--no-predict``;
    ``--core``: on the core), print it (``line`` formats one record), and return its scenario, records, table
    row (None when the chain did not let it end) and surprises (a mission not reached, a violation, a
    denied command, a run that did not end).  The chain always has a predictor: the pilot commands only
    from a step whose prediction came.  ``live`` (``--live``): ``session`` is the live one, without a
    predictor yet; each skill runs 2 s divided by ``--speed``, and each change of the pilot's status is
    printed as it comes.  ``then`` is called with the result while the chain still runs (its pilot too: a
    live run's views keep a pilot that answers), before the chain closes."""
    run, system = entry.run, entry.system
    failures = ", ".join(f"run {f.run} of {f.skillset}:{f.skill} ends {f.mode}" for f in run.failures) or "none"
    print(f"== {run.name} run ({entry.path}): {len(entry.goals)} goals ({entry.goals_path}), {run.mode} mode, "
          f"system {system.name}")
    print(f"   failures injected: {failures}")
    if args.core:
        from skinet.pilot.flight import fly

        flight = fly(system, entry.goals, Outcomes.of(run, system))
        scenario = Scenario(run.name, run.system, tuple(Step(float(n), s, t) for n, (s, t) in enumerate(flight.moves)))
        end, reason, denied, monitor_violations, sent = flight.end, flight.reason, None, None, None
        print("   chain: core only (the pilot's drive mode on the live nets; no simulator, Zenoh, check)")
    else:
        from chains.chain import ChainError
        from chains.pilot_chain import run_pilot_chain  # Zenoh only when the chain runs

        speed = 1.0 if getattr(args, "speed", None) is None else args.speed
        duration = (LIVE_SKILL_SECONDS / speed if speed > 0 else SKILL_SECONDS) if live else SKILL_SECONDS
        try:
            played: list[PlayedPilot] = []

            def finish(record: PilotRecord) -> None:
                print("   chain: simulated managers (skills end by themselves) -> CDR -> bridge -> monitor -> "
                      "predictor -> pilot -> check (strict) -> requests on the managers' topics, embedded Zenoh "
                      "session")
                played.append(_tally(args, entry, line, record.scenario(), record.status.state,
                                     record.status.reason, record.status.denied, len(record.violations),
                                     record.commands))
                if then is not None:
                    then(played[0])

            run_pilot_chain(system, load_typemap(entry.path.parent / run.system), run, entry.mission,
                            mission_name=str(entry.goals_path), duration=duration, session=session,
                            shared_predictor=session is not None and not args.no_predict and not live,
                            timeout=120.0 + 200 * duration, on_status=_printer() if live else None, then=finish)
            return played[0]
        except ChainError as exc:  # the run did not end: said, and counted as a surprise
            print(f"   pilot: the run did not end: {exc}")
            failed = Scenario(run.name, run.system, ()), [], None, [f"the pilot run did not end: {exc}"]
            if then is not None:
                then(failed)
            return failed
    played_core = _tally(args, entry, line, scenario, end, reason, denied, monitor_violations, sent)
    if then is not None:
        then(played_core)
    return played_core


def _tally(args: argparse.Namespace, entry: PilotEntry, line: Callable[[StepRecord], str], scenario: Scenario,
           end: str, reason: str, denied: int | None, monitor_violations: int | None, sent: int | None,
           ) -> PlayedPilot:
    """The run replayed on the core, printed, with its table row and surprises."""
    run, system = entry.run, entry.system
    records = replay(system, scenario, predict=not args.no_predict)
    for r in records:
        if args.all_steps or r.violations or r.divergence or ".failure" in (r.step.transition or ""):
            print(line(r))
    row = tally(run.name, records, denied)
    if monitor_violations is not None:  # the chain: measured on the robot's side, not replayed
        row.violations, row.commands = monitor_violations, sent
    print(f"   pilot: {end}{': ' + reason if reason else ''}; {len(entry.goals)} goals, {row.moves} moves, "
          f"{row.commands} commands sent" + ("" if denied is None else f", {denied} denied by the check")
          + f", {row.retries} retries")
    print(f"   violations: {row.violations}")
    surprises = [f"the pilot's mission ended {end}: {reason}"] if end != "reached" else []
    surprises += [f"{row.violations} violations under the pilot"] if row.violations else []
    surprises += [f"the check denied {denied} of the pilot's commands"] if denied else []
    surprises += [f"step {r.index} ({r.step.skillset}:{r.step.transition}) does not replay on the model: "
                  f"{r.divergence}" for r in records if r.divergence]
    replayed = sum(len(r.violations) for r in records)
    if monitor_violations is not None and replayed != monitor_violations:
        surprises.append(f"the monitor showed {monitor_violations} violations, the core replay {replayed}")
    return scenario, records, row, surprises


def _printer() -> Callable[[PilotStatus], None]:
    """Prints a line per change of the pilot's status, as ``skinet goal`` does (the statuses of a live run)."""
    from chains.pilot_lines import StatusLines

    lines = StatusLines(say_mode=False)
    lock = threading.Lock()

    def on_status(status: PilotStatus) -> None:
        with lock:
            line = lines.line(status) if status.goal_id else None
            if line is not None:
                print(f"   pilot: {line}", flush=True)
    return on_status


def tally(name: str, records: list[StepRecord], denied: int | None = None) -> Row:
    """The table row of a run from its records."""
    steps = [r.step.transition for r in records if r.step.transition is not None]
    return Row(name, sum(t.endswith((".start", ".interrupt")) for t in steps), len(steps),
               sum(".failure" in t for t in steps), sum(len(r.violations) for r in records), denied)


def table(rows: list[Row]) -> str:
    """The runs side by side."""
    width = max([len("run"), *(len(r.name) for r in rows)])
    lines = ["== the runs side by side",
             f"   {'run':<{width}}  commands  moves  retries  violations  denied"]
    for r in rows:
        lines.append(f"   {r.name:<{width}}  {r.commands:>8}  {r.moves:>5}  {r.retries:>7}  {r.violations:>10}  "
                     f"{'-' if r.denied is None else r.denied:>6}")
    return "\n".join(lines)


__all__ = ["PilotEntry", "Row", "load_pilot_entry", "play_pilot", "table", "tally"]
