"""``skinet demo``: the paper's two runs, as the operator would have seen them."""

from __future__ import annotations

import argparse
import importlib.resources
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from skinet.errors import SkinetError, SourceError
from skinet_cli.demo_pilot import PilotEntry, PlayedPilot, Row, load_pilot_entry, play_pilot, table, tally
from skinet_cli.live_demo import add_live_args, live_options_misused, live_session, play_live
from services.common.options import add_no_properties_arg, load_live_system, require_properties
from skinet.verify.explain import plural, warning_line
from skinet.system.load import load_goals, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import Scenario, StepRecord, check_scenario, flagged_before, parse_scenario, replay
from skinet.mission.log import records_to_log
from skinet.pilot.run import is_pilot_run
from skinet.system.model import System
from skinet.wire.log import log_line

if TYPE_CHECKING:
    import zenoh

MISSIONS = ("unassisted.toml", "assisted.toml", "pilot.toml", "mobile_unassisted.toml", "mobile_assisted.toml")
UNEXPECTED = 3  # exit status: a divergence the scenario did not declare, or a declared one that did not happen
EXAMPLES = {"nav2": Path("examples") / "nav2" / "missions" / "nav2_run.toml"}  # skinet demo nav2
HELP = (f"play {len(MISSIONS)} runs: the paper's unassisted and assisted runs, the paper's mission driven by the "
        "pilot, then the mobile manipulator's two (the main job)")
DESCRIPTION = (
    f"Play {len(MISSIONS)} runs through the whole chain (simulated managers, CDR, bridge, monitor, predictor on one "
    "embedded Zenoh session) and print what the operator would have seen: the paper's unassisted run "
    "(three violations) and assisted run (two warnings heeded, no violation), the same mission driven by the "
    "pilot from a goals file with two failures injected (retried; no violation, no command denied), then the "
    "mobile manipulator's unassisted and assisted runs (a forced constraint), and a table of the runs side by "
    "side (commands, moves, retries, violations, denied). Given SCENARIO files (or pilot run files, with a "
    "[pilot] table), it plays those instead; 'nav2' "
    "plays a Nav2 base that has no skillset manager, bound to its action servers, lifecycle node and topics "
    "(examples/nav2). A step the model does not allow then is shown as a model divergence. Exit status: 0; 3 when "
    "a run diverged at a step its scenario does not mark expect_divergence = true, or a marked step did not "
    "diverge, or a pilot run did not reach its goals, saw a violation or had a command denied; 1 on bad input. "
    "With --live it plays one run (the paper's unassisted run by default; a pilot run too, each skill lasting "
    "2 s at speed 1, the pilot's status printed as it changes) in real time, "
    "served on Zenoh for skinet watch, skinet dashboard and skinet check (it prints their lines), and with "
    "--dashboard PORT serves the dashboard itself.")


def demo_roots() -> list[Path]:
    """Where the demo's files are looked for, in order: the current folder (a checkout), the files an
    installed wheel ships (``skinet_cli/demo_files``, copied by ``setup.py``), the checkout an editable
    install runs from."""
    shipped = Path(str(importlib.resources.files("skinet_cli"))) / "demo_files"
    return [Path.cwd(), shipped, Path(__file__).resolve().parents[1]]


def default_scenarios() -> list[Path]:
    """The paper's runs: ``skillsets/missions/`` in the first of :func:`demo_roots` that has them all."""
    for root in demo_roots():
        folder = root / "skillsets" / "missions"
        if all((folder / m).exists() for m in MISSIONS):
            return [folder / m for m in MISSIONS]
    return [Path("skillsets/missions") / m for m in MISSIONS]


def example_scenario(name: str) -> Path:
    """The scenario of a named example (``nav2``), in the first of :func:`demo_roots` that has it."""
    for root in demo_roots():
        if (root / EXAMPLES[name]).exists():
            return root / EXAMPLES[name]
    return EXAMPLES[name]


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("demo", help=HELP, description=DESCRIPTION)
    c.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                   help=f"scenario files or pilot run files ([pilot]: a goals file driven by the pilot, with "
                        f"injected failures) (default: the {len(MISSIONS)} runs above, skillsets/missions/"
                        f"{{{','.join(m.removesuffix('.toml') for m in MISSIONS)}}}.toml), or 'nav2' (examples/nav2)")
    c.add_argument("--no-predict", action="store_true", help="explicit constraints only")
    add_no_properties_arg(c)
    c.add_argument("--core", action="store_true",
                   help="replay on the core library only (no simulator, ROS 2 encoding, bridge, Zenoh)")
    c.add_argument("--all-steps", action="store_true", help="print every step, not only the notable ones")
    c.add_argument("--log", metavar="DIR", help="write each run as a monitor log DIR/<run>.jsonl (see skinet timeline)")
    c.add_argument("--timeline", metavar="DIR", help="draw each run as an operator timeline DIR/<run>.png")
    add_live_args(c)
    c.set_defaults(func=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    misused = live_options_misused(args)
    if misused or (args.live and (args.core or len(args.scenarios) > 1)):
        raise SkinetError(misused or ("--live plays the whole chain, not --core" if args.core else
                                      f"--live plays one run at a time (got {len(args.scenarios)} scenarios)"))
    paths = [example_scenario(p) if p in EXAMPLES else Path(p) for p in args.scenarios] or (
        default_scenarios()[:1] if args.live else default_scenarios())
    for folder in {args.log, args.timeline} - {None}:  # before the runs, not after the first one
        try:
            Path(folder).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SourceError.at(folder, None, f"cannot create folder: {exc.strerror}") from None
    runs: list[tuple[Path, Scenario, System] | PilotEntry] = []
    for path in paths:  # every file checked before the first run starts
        text = read_text(path)
        if is_pilot_run(text):
            runs.append(load_pilot_entry(path, text, args.no_properties))
            continue
        scenario = parse_scenario(text, str(path))
        system, _ = load_live_system(path.parent / scenario.system)
        require_properties(system, path.parent / scenario.system, args.no_properties)
        check_scenario(scenario, system, str(path))
        if scenario.pilot:
            load_goals(path.parent / scenario.pilot, system, load_typemap(path.parent / scenario.system))
        runs.append((path, scenario, system))
    if args.live:
        return _live_pilot(args, runs[0]) if isinstance(runs[0], PilotEntry) else _live(args, *runs[0])
    if args.core:
        return _play(args, runs, None)
    from chains.chain import shared_session  # Zenoh only when the chain runs

    with shared_session(predict=not args.no_predict) as session:  # one predictor for every run
        return _play(args, runs, session)


def _play(args: argparse.Namespace, runs: list[tuple[Path, Scenario, System] | PilotEntry],
          session: zenoh.Session | None) -> int:
    """Play ``runs`` one after the other (on ``session`` and its predictor, or on the core), print them and the
    table of the runs side by side; the exit status."""
    surprises: list[str] = []
    rows: list[Row] = []
    chain = dict(session=session, shared_predictor=True)
    for entry in runs:
        if isinstance(entry, PilotEntry):
            scenario, records, row, found = play_pilot(args, entry, _line, session)
            rows += [row] if row is not None else []
            surprises += [f"{entry.path}: {s}" for s in found]
            if (args.log or args.timeline) and records:
                _write_run(args, entry.system, scenario, records)
            print()
            continue
        path, scenario, system = entry
        piloted: list[Any] = []  # what the pilot did after the run (scenario.pilot, bound systems)
        if args.core:
            records = replay(system, scenario, predict=not args.no_predict)
            how = "core replay"
        else:
            from chains.chain import run_any_chain  # Zenoh only when the chain runs

            records = run_any_chain(system, path.parent / scenario.system, scenario, predict=not args.no_predict,
                                    then=_pilot_after_run(path, scenario, piloted), **chain)
            how = ("simulated action servers, lifecycle node and topics -> CDR -> bridge (bindings) -> monitor -> "
                   "predictor, embedded Zenoh session" if any(c.binding for c in system.components) else
                   "simulated managers -> CDR -> bridge -> monitor -> predictor, embedded Zenoh session")
        steps = sum(r.step.transition is not None for r in records)  # considered commands are no steps
        print(f"== {scenario.name} run ({path}): {steps} steps, system {system.name}")
        print(f"   chain: {how}")
        for r in records:
            if args.all_steps or r.violations or r.warnings or r.flagged or r.divergence or r.step.consider:
                print(_line(r))
        print(_summary(records))
        if scenario.pilot and piloted:
            print(_pilot_lines(path.parent / scenario.pilot, piloted[0]))
        elif scenario.pilot:
            print(f"   (the pilot's goals, {path.parent / scenario.pilot}, need the chain of a bound system: not "
                  "played here)")
        rows.append(tally(scenario.name, records))
        surprises += [f"{path}: {s}" for s in unexpected(records)]
        if args.log or args.timeline:
            _write_run(args, system, scenario, records)
        print()
    print(table(rows))
    for line in surprises:
        print(f"skinet demo: {line}", file=sys.stderr)
    return UNEXPECTED if surprises else 0


def _live(args: argparse.Namespace, path: Path, scenario: Scenario, system: System) -> int:
    """``--live``: each step printed as the monitor showed it, the summary at the end (skinet_cli.live_demo)."""
    header = (f"== {scenario.name} run ({path}), live at speed {1.0 if args.speed is None else args.speed:g}: "
              f"{sum(s.transition is not None for s in scenario.steps)} steps, system {system.name}")
    surprises: list[str] = []
    piloted: list[Any] = []  # what the pilot did after the run (scenario.pilot, bound systems)

    def after(records: list[StepRecord]) -> None:
        print(_summary(records), flush=True)
        if piloted:
            print(_pilot_lines(path.parent / scenario.pilot, piloted[0]), flush=True)
        surprises.extend(f"{path}: {s}" for s in unexpected(records))
        for line in surprises:
            print(f"skinet demo: {line}", file=sys.stderr, flush=True)
        if args.log or args.timeline:
            _write_run(args, system, scenario, records)

    speed = 1.0 if args.speed is None else args.speed
    then = _pilot_after_run(path, scenario, piloted, 2.0 / speed if speed > 0 else 0.05) if any(
        c.binding for c in system.components) else None  # a skill takes 2 s at speed 1
    play_live(args, path, scenario, system, header, lambda r: print(_line(r), flush=True), after, then)
    return UNEXPECTED if surprises else 0


def _live_pilot(args: argparse.Namespace, entry: PilotEntry) -> int:
    """``--live`` on a pilot run: the pilot drives the run's goals on a live session, each change of its status
    printed as it comes, the run printed at the end as without ``--live`` (skinet_cli.live_demo)."""
    speed = 1.0 if args.speed is None else args.speed
    header = f"== live at speed {speed:g}: the pilot drives the run below, its status as it changes"
    with live_session(args, entry.system, header) as (session, linger):
        def over(played: PlayedPilot) -> None:  # the chain and its pilot still run: the views keep both
            scenario, records, _, surprises = played
            for line in surprises:
                print(f"skinet demo: {entry.path}: {line}", file=sys.stderr, flush=True)
            if (args.log or args.timeline) and records:
                _write_run(args, entry.system, scenario, records)
            linger()

        surprises = play_pilot(args, entry, _line, session, live=True, then=over)[3]
    return UNEXPECTED if surprises else 0


def _pilot_after_run(path: Path, scenario: Scenario, piloted: list[Any], duration: float = 0.05) -> Any:
    """The ``then`` of a bound chain run whose scenario names goals for the pilot (``[scenario] pilot``): the pilot
    drives them from where the run left the robot, each goal lasting ``duration`` s (what it did goes to
    ``piloted``); ``None`` without such goals."""
    if not scenario.pilot:
        return None
    from chains.bound_pilot import drive_goals  # Zenoh only when the chain runs

    goals = path.parent / scenario.pilot
    return lambda chain: piloted.append(drive_goals(chain, read_text(goals), str(goals), duration=duration))


def unexpected(records: list[StepRecord]) -> list[str]:
    """Divergences at steps without ``expect_divergence``, and marked steps that did not diverge."""
    out = []
    for r in records:
        if r.step.transition is None or bool(r.divergence) == r.step.expect_divergence:
            continue
        what = f"step {r.index} ({r.step.skillset}:{r.step.transition} at t={r.step.t:g} s)"
        out.append(f"{what}: model divergence the scenario does not expect (mark it expect_divergence = true): "
                   f"{r.divergence}" if r.divergence else f"{what}: expected a model divergence, none happened")
    return out


def _write_run(args: argparse.Namespace, system: System, scenario: Scenario, records: list[StepRecord]) -> None:
    """``--log`` and ``--timeline``: the run as the monitor would have published it."""
    entries = records_to_log(system, scenario, records, predict=not args.no_predict)
    stem = re.sub(r"[^A-Za-z0-9_.\-]", "_", scenario.name) or "run"
    if args.log:
        path = Path(args.log) / f"{stem}.jsonl"
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("".join(log_line(e.key, e.message, e.t) + "\n" for e in entries), encoding="utf-8")
        except OSError as exc:
            raise SourceError.at(str(path), None, f"cannot write file: {exc.strerror}") from None
        print(f"   log: {path} ({len(entries)} messages)")
    if args.timeline:
        from skinet_cli.timeline import save_timeline

        title = f"{system.name}: {scenario.name} run"
        path = save_timeline(entries, title, Path(args.timeline) / f"{stem}.png", system)
        print(f"   timeline: {path}")


def _summary(records: list[StepRecord]) -> str:
    """What was violated, whether SkiNet had flagged the command that led there, and which warnings were heeded."""
    lines = []
    violations = [(p, r.index) for r in records for p in r.violations]
    lines.append(f"   violations: {len(violations)}" + "".join(f"; {p} at step {i}" for p, i in violations))
    for p, i in violations:
        found = flagged_before(records, i, p)
        if found is None:
            lines.append(f"     {p} at step {i}: SkiNet had not flagged any command issued before it")
        else:
            j, u = found
            ahead = "the command itself" if j == i else f"{plural(i - j)} ahead"
            lines.append(f"     {p} at step {i}: SkiNet flagged {u.skillset}:{u.transition} when it was issued at "
                         f"step {j} ({u.constraint}, {ahead}); the operator went ahead")
    diverged = [r for r in records if r.divergence]
    lines.append(f"   divergences: {len(diverged)}" + "".join(
        f"; {r.step.skillset}:{r.step.transition} at step {r.index}"
        f" ({'expected' if r.step.expect_divergence else 'NOT EXPECTED'})" for r in diverged))
    heeded = [(w, r.index) for r in records for w in r.warnings]
    lines.append(f"   warnings heeded (commands considered, flagged, not issued): {len(heeded)}"
                 + "".join(f"; {w.skillset}:{w.transition} {w.constraint} for {w.property} at step {i}"
                           for w, i in heeded))
    return "\n".join(lines)


def _pilot_lines(goals: Path, end: Any) -> str:
    """What the pilot did after the run (:class:`chains.bound_pilot.PilotEnd`)."""
    status = end.status
    lines = [f"   then the pilot, in drive mode through the bindings: {', '.join(status.goals)} ({goals}): "
             f"{end.reply.answer}, {plural(end.reply.moves or 0, 'move')} when outcomes are favourable"]
    lines += [f"     sent: {s}" for s in end.sent]
    lines.append(f"     robot: {', '.join(end.transitions) or 'nothing'}")
    lines.append(f"   pilot: {status.state}{': ' + status.reason if status.reason else ''}; "
                 f"{plural(status.commands, 'command')} sent, {status.denied} denied; "
                 f"violations: {len(end.violations)}" + "".join(f"; {p}" for p in end.violations))
    return "\n".join(lines)


def _line(r: StepRecord) -> str:
    s = r.step
    what = f"{s.skillset}:{s.transition}" if s.transition else f"(considers {s.skillset}:{s.consider})"
    status = " ".join(f"{p}={'ok' if ok else 'VIOLATED'}" for p, ok in r.holds.items())
    line = f"  step {r.index:>3}  t={s.t:>6.1f}s  {what:<42} {status}  unsafe={r.unsafe_count}"
    for u in r.flagged:
        line += f"\n             SkiNet had flagged it: {warning_line(u)}"
    for p in r.violations:
        line += f"\n             !! {p} violated"
    for p, names in r.recovery.items():
        line += f"\n             {p} is violated now; recovery: {', '.join(names) or 'none'}"
    for w in r.warnings:
        line += f"\n             SkiNet: {warning_line(w)}; operator refrains"
    if r.divergence:
        line += f"\n             model divergence: {r.divergence}"
    if s.note:
        line += f"\n             ({s.note})"
    return line
