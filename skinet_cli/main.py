"""The ``skinet`` command line: a thin shell over the core library."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

# Before numpy is imported: its OpenBLAS starts a thread per core at import, 35 ms of CPU
# (a sixth of `skinet unsafe`), and the core library does no linear algebra.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from skinet import __version__
from skinet.errors import SkinetError, SourceError
from skinet.files import program
from skinet.verify.explain import plural
from skinet.system.load import load_model
from skinet.net.build import build_net
from skinet.net.export import FORMATS
from skinet.props.parser import parse_formula
from skinet.system.model import System, marking_problems, marking_to_json
from skinet.verify.algorithm1 import analyse
from skinet.verify.ctl import Kripke, check
from skinet.verify.explore import Deadline, explore
from skinet.verify.predict import Forecast, forecast
from services.common.environment import check_environment
from services.common.options import ArgumentParser, count, load_live_system, print_warnings, state_marking
from services.common.options import seconds as duration, time_budget
from services.common.memory import add_memory_arg, memory_limit
from services.common.stacks import stacks_on_sigusr1
from chains.render import analysis_text, seconds, table

DESCRIPTION = """\
SkiNet Live: predictive runtime verification of skill-based robots.
Turns ONERA robot-language skillsets (.rl) into Petri nets, checks safety
properties and reports the commands and events that would violate them now
(explicit constraints), inevitably later (implicit constraints: AF not phi,
fair by default) or through skill outcomes no command can prevent (forced
constraints)."""

EPILOG = """\
examples (from the repository's root; tests/cli/test_help_examples.py runs every one):
  skinet demo
  skinet parse skillsets/spot.rl
  skinet net skillsets/spot.rl --eventless --format tina -o spot.net
  skinet unsafe skillsets/spot_arm.toml --state skillsets/states/arm_at_RD.json
  skinet unsafe skillsets/spot_arm.toml --state '{"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"}, "running": ["teleop"]}}'
  skinet explore skillsets/spot_arm.toml --budget 2
  skinet ctl skillsets/spot_arm.toml "AG not (spot:Busy and manipulator:Busy)" "EF spot:Busy"
  skinet conform examples/nav2/nav2.toml examples/nav2/bags/nav2_run
  skinet plan skillsets/spot_arm.toml "reach spot:Standing and manipulator:RD"

a live system, one command per terminal (skinet run prints the lines that reach it;
Ctrl-C stops the ones that keep running):
  skinet run skillsets/spot_arm.toml --listen tcp/127.0.0.1:7447 --dashboard 8080
  python -m services.bridge_ros2 skillsets/spot_arm.toml -e tcp/127.0.0.1:7447
  skinet watch spot_arm -e tcp/127.0.0.1:7447
  skinet record spot_arm -o run.jsonl -e tcp/127.0.0.1:7447
  python -m services.simulator skillsets/missions/unassisted.toml -e tcp/127.0.0.1:7447 --speed 10
  skinet check spot_arm spot:teleop.start -e tcp/127.0.0.1:7447
  skinet timeline run.jsonl -o run.png

through a router with logins (it makes the passwords at its first start; --user with
--connect makes a session a client of the router):
  skinet router --listen tcp/127.0.0.1:7448
  skinet run skillsets/spot_arm.toml -e tcp/127.0.0.1:7448 --user monitor --password-file ~/.config/skinet/secrets/monitor.password
  skinet dashboard spot_arm -e tcp/127.0.0.1:7448 --user observer --password-file ~/.config/skinet/secrets/observer.password --port 8081

state (--state) is a JSON file or the JSON itself, {"SKILLSET": {"resources": {...},
"running": [...]}}; omitted resources are initial, omitted skills idle."""

PROGRESS_EVERY = 0.2  # seconds between progress reports of an exploration

# Commands whose modules import Zenoh, pydantic messages, aiohttp or plotting, in --help order:
# (module, function registering its commands, {command: one-line help}).  Only the module of
# the command being run is imported; the others are listed by name and help alone, so that
# `skinet unsafe` does not pay for them (issue 10 (d); tests/cli/test_cli.py checks that the
# helps here are the modules' own).
LAZY_COMMANDS: tuple[tuple[str, str, dict[str, str]], ...] = (
    ("skinet_cli.demo", "add_parser", {"demo": "play 5 runs: the paper's unassisted and assisted runs, the paper's "
                                               "mission driven by the pilot, then the mobile manipulator's two (the "
                                               "main job)"}),
    ("skinet_cli.record", "add_parser",
     {"record": "record the monitor's messages of a system into a JSON Lines log",
      "rosbag": "record the robot's ROS 2 topics the bridge reads into a rosbag2 (no ROS needed)"}),
    ("skinet_cli.timeline", "add_parser",
     {"timeline": "draw a monitor log (skinet record, skinet demo --log) as a timeline picture"}),
    ("skinet_cli.replay", "add_parser",
     {"replay": "publish a recorded run (skinet record) again, for dashboard and watch"}),
    ("skinet_cli.conform", "add_parser",
     {"conform": "replay rosbag2 files against the model and report every divergence"}),
    ("skinet_cli.run", "add_commands", {
        "run": "monitor, predictor and pilot in one process with a live operator view (docs/semantics.md §7, §8)",
        "router": "run a Zenoh router (the Python wheel in router mode) until interrupted",
        "fleet": "link robots' routers to a hub over mutual TLS: exchange the trust files",
    }),
    ("skinet_cli.plan", "add_parser",
     {"plan": "plan the commands that reach a goal without violating any property (docs/semantics.md §8)"}),
    ("skinet_cli.goal", "add_parser",
     {"goal": "give a running pilot a goal (guide or drive) and follow it until it ends (docs/semantics.md §8)"}),
    ("skinet_cli.operator", "add_parsers", {
        "dashboard": "live web dashboard of a running system (served on 127.0.0.1:8080)",
        "watch": "terminal live view of a running system (any deployment)",
        "check": "ask a running monitor whether a command is safe now (skinet/<system>/check)",
    }),
    ("skinet_cli.foxglove", "add_parser",
     {"foxglove": "serve a running system to Foxglove (WebSocket on 127.0.0.1:8765)"}),
    ("skinet_cli.client_config", "add_parser", {
        "client-config": "write the Zenoh client configuration (TLS, login) of one user from a deployment's secrets",
    }),
)


def _command(argv: Sequence[str]) -> str:
    """The subcommand named on a command line ("" when none): skinet's own options take no value."""
    return next((a for a in argv if not a.startswith("-")), "")


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    stacks_on_sigusr1()  # a hung command: ``kill -USR1 PID`` shows where
    try:
        parser = build_parser(_command(argv))
        args = parser.parse_args(argv)
    except KeyboardInterrupt:  # Ctrl-C while starting (importing, parsing): no traceback
        print("skinet: interrupted", file=sys.stderr)
        return 130
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        check_environment()
        return int(args.func(args) or 0)
    except SourceError as exc:
        print(str(exc), file=sys.stderr)
        return 1
    except SkinetError as exc:
        print(f"skinet: error: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # a name that cannot be a Zenoh key (skinet/wire/keys.py)
        print(f"skinet: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("skinet: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    except Exception as exc:  # a bug: still one line, the traceback on request
        if os.environ.get("SKINET_TRACEBACK"):
            raise
        print(f"skinet: internal error: {type(exc).__name__}: {exc} (a bug: please report it; "
              "SKINET_TRACEBACK=1 shows the traceback)", file=sys.stderr)
        return 70


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole parser; with ``command``, only that command's module of :data:`LAZY_COMMANDS` is imported."""
    p = ArgumentParser(
        prog="skinet", description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--version", action="version", version=f"skinet {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    c = sub.add_parser("parse", help="check a .rl skillset file and summarise it")
    c.add_argument("file", help="skillset model (.rl)")
    c.add_argument("--json", action="store_true", help="machine-readable summary")
    c.set_defaults(func=cmd_parse)

    c = sub.add_parser("net", help="print the Petri net of a skillset or of a system's union (docs/semantics.md §3)")
    c.add_argument("file", help="skillset model (.rl), or system file (.toml) for the union of its skillsets")
    c.add_argument("--eventless", action="store_true", help="the eventless net SkN^e (no event transitions)")
    c.add_argument("--format", choices=sorted(FORMATS), default="json", help="output format (default: json)")
    c.add_argument("-o", "--output", help="write to this file instead of standard output")
    c.set_defaults(func=cmd_net)

    c = sub.add_parser("unsafe", help="Algorithm 1: unsafe transitions at a marking (docs/semantics.md §5)")
    _system_args(c)
    c.add_argument("--no-predict", action="store_true", help="explicit constraints only (mu1 empty)")
    c.add_argument("--literal", action="store_true",
                   help="also print the literal algorithm's list (it flags transitions for properties already violated)")
    c.set_defaults(func=cmd_unsafe)

    c = sub.add_parser("explore", help="explore the eventless state space and compute mu1 (docs/semantics.md §6)")
    _system_args(c)
    c.add_argument("--progress", action="store_true",
                   help=f"print the layer and markings so far on standard error every {PROGRESS_EVERY:g} s (on a "
                        "terminal this is the default), or say the run was too short to need it")
    c.set_defaults(func=cmd_explore)

    c = sub.add_parser("ctl", help="model-check CTL formulas on the explored state space")
    _system_args(c)
    c.add_argument("formulas", nargs="+", metavar="FORMULA",
                   help='one or more formulas, e.g. "AG not (spot:Busy and manipulator:Busy)" (one exploration for all)')
    c.set_defaults(func=cmd_ctl)

    for module, register, helps in LAZY_COMMANDS:
        if command is None or command in helps:
            getattr(importlib.import_module(module), register)(sub)
        else:
            for name, summary in helps.items():
                sub.add_parser(name, help=summary)
    return p


def _system_args(c: argparse.ArgumentParser) -> None:
    c.add_argument("system", help="system file (.toml), e.g. skillsets/spot_arm.toml")
    c.add_argument("--state", metavar="STATE",
                   help="start marking: a JSON file, or the JSON itself ('{\"spot\": {...}}'); omitted resources are "
                        "initial, omitted skills idle (default: the initial marking)")
    c.add_argument(
        "--what-if", action="store_true",
        help="accept a --state the robot cannot be in (an invariant violated, or unreachable) for what-if analysis",
    )
    c.add_argument("--budget", type=time_budget(), default=10.0,
                   help="exploration time budget in seconds, at most 86400 (default: 10)")
    c.add_argument("--max-depth", type=count(0), help="expand at most this many breadth-first layers")
    add_memory_arg(c)
    c.add_argument("--no-seeds", action="store_true", help="do not seed exploration with firable events")
    c.add_argument("--json", action="store_true", help="machine-readable result")
    c.add_argument("--af", choices=["fair", "literal"],
                   help="AF for implicit constraints, all properties (default: the system file's [prediction] "
                        "table, else fair: only paths on which running skills end count; literal: the paper's)")
    c.add_argument("--events-uncontrollable", action="store_true", default=None,
                   help="count events as uncontrollable steps for forced constraints (default: off)")
    c.add_argument("--no-forced", dest="forced", action="store_false", default=None,
                   help="do not report forced constraints (skill outcomes alone lead to a violation)")


def _load(args: argparse.Namespace) -> tuple[System, dict[str, int]]:
    system, warnings = load_live_system(args.system)
    print_warnings(warnings)
    system = replace(system, prediction=system.prediction.override(
        af=args.af, forced=args.forced, events_uncontrollable=args.events_uncontrollable))
    marking = system.initial_marking() if args.state is None else state_marking(args.state, system, args.what_if)[0]
    for problem in marking_problems(system, marking) if args.what_if else ():
        print(f"what-if analysis: {problem}", file=sys.stderr if args.json else sys.stdout)
    return system, marking


def _forecast(args: argparse.Namespace, system: System, marking: dict[str, int], full: bool = False) -> Forecast:
    asked = getattr(args, "progress", False)
    show, tty = asked or (sys.stderr.isatty() and not args.json), sys.stderr.isatty()
    last, shown = [0.0], [0]

    def progress(depth: int, markings: int, elapsed: float) -> None:
        if show and elapsed - last[0] >= PROGRESS_EVERY:
            last[0] = elapsed
            shown[0] += 1
            line = f"  layer {depth}: {plural(markings, 'marking')}, {seconds(elapsed)}"
            print(f"\r{line}" if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    result = forecast(
        system, marking, budget=args.budget, max_depth=args.max_depth, event_seeds=not args.no_seeds, progress=progress,
        full=full, memory_limit=memory_limit(args),
    )
    if shown[0] and tty:
        print(file=sys.stderr)
    elif asked and not shown[0]:
        print(f"progress: none to show, the exploration took {seconds(time.perf_counter() - t0)} (a report comes "
              f"every {PROGRESS_EVERY:g} s)", file=sys.stderr)
    return result


def _emit(data: object) -> None:
    print(json.dumps(data, indent=2))


def cmd_parse(args: argparse.Namespace) -> int:
    if args.file.endswith(".toml"):
        raise SourceError.at(args.file, None, "this is a system or scenario file (.toml); skinet parse checks a "
                                              f"skillset model (.rl): for a system try {program.skinet()} net {args.file} or "
                                              f"{program.skinet()} unsafe {args.file}")
    model = load_model(args.file)
    print_warnings(model.warnings)
    summary = [
        {
            "skillset": s.name,
            "resources": {r.name: {"states": list(r.states), "initial": r.initial} for r in s.resources},
            "events": [e.name for e in s.events],
            "skills": [k.name for k in s.skills],
        }
        for s in model.skillsets
    ]
    if args.json:
        _emit(summary)
        return 0
    for s in summary:
        print(f"skillset {s['skillset']} ({args.file})")
        print(f"  resources ({len(s['resources'])}):")
        for name, r in s["resources"].items():
            print(f"    {name}: {' '.join(r['states'])} (initial {r['initial']})")
        print(f"  events ({len(s['events'])}): {' '.join(s['events']) or '-'}")
        print(f"  skills ({len(s['skills'])}): {' '.join(s['skills']) or '-'}")
    return 0


def cmd_net(args: argparse.Namespace) -> int:
    from skinet.net.union import union

    if args.file.endswith(".toml"):  # a system file: the union of its skillsets' nets
        system, warnings = load_live_system(args.file)
        print_warnings(warnings)
        nets = [c.eventless if args.eventless else c.net for c in system.components]
        name = system.name
    else:
        model = load_model(args.file)
        print_warnings(model.warnings)
        nets = [build_net(s, eventless=args.eventless) for s in model.skillsets]
        name = Path(args.file).stem
    text = FORMATS[args.format](nets[0] if len(nets) == 1 else union(nets, name))
    if args.output:
        try:
            Path(args.output).write_text(text)
        except OSError as exc:
            raise SourceError.at(args.output, None, f"cannot write file: {exc.strerror}") from None
    else:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0


def cmd_unsafe(args: argparse.Namespace) -> int:
    system, marking = _load(args)
    prediction = None if args.no_predict else _forecast(args, system, marking)
    result = analyse(system, marking, prediction)
    if args.json:
        _emit({
            "system": system.name,
            "marking": marking_to_json(system, marking),
            "violated": result.violated,
            "unsafe": [u.__dict__ | {"witness": list(u.witness)} for u in result.operator_unsafe()],
            "options": {p.name: system.prediction.of(p.name).__dict__ for p in system.properties},
            "recovery": {p: [r.__dict__ for r in rs] for p, rs in result.recovery.items()},
            **({"literal": [u.__dict__ | {"witness": list(u.witness)} for u in result.unsafe]} if args.literal else {}),
            "prediction": None if prediction is None else prediction.report(),
        })
        return 0
    print(analysis_text(system, result, args.literal))
    if prediction is not None:
        r = prediction.report()
        state = "complete" if r["complete"] else (
            f"TRUNCATED by {r['truncated_by']} ({prediction.space.explored()}; unknown constraints possible)")
        print(f"prediction: {state}, {plural(r['markings'], 'marking')} in {seconds(r['elapsed'])}")
    else:
        print("prediction: off (explicit constraints only)")
    return 0


def cmd_explore(args: argparse.Namespace) -> int:
    system, marking = _load(args)
    result = _forecast(args, system, marking, full=True)
    report = result.report()
    if args.json:
        _emit({"system": system.name, **report})
        return 0
    print(f"explored {system.name} ({'with' if not args.no_seeds else 'without'} event seeds)")
    rows = [
        ["complete", "yes" if report["complete"] else f"no (truncated by {report['truncated_by']}: {result.space.explored()})"],
        ["elapsed", seconds(report["elapsed"])],
        ["depth", report["depth"] if report["depth"] >= 0 else "none (no layer expanded)"],
        ["markings", report["markings"]],
        ["edges", report["edges"]],
        ["deadlocks", report["deadlocks"]],
        ["frontier", report["frontier"]],
    ]
    print("\n".join("  " + line for line in table(rows, ["", ""]).splitlines()[1:]))
    props = [
        [n, c["violating"], c["implicit_fair"], c["implicit_literal"], c["forced"],
         f"{c['undecided_fair']} / {c['undecided_literal']}", report["af"][n]]
        for n, c in report["properties"].items()
    ]
    if props:
        print(table(props, ["property", "violating", "implicit (fair)", "implicit (literal)", "forced",
                            "undecided (fair / literal)", "operator AF"]))
        print("implicit and forced count markings where the property still holds; mu1 = violating + implicit")
    return 0


def cmd_ctl(args: argparse.Namespace) -> int:
    system, marking = _load(args)
    skillsets = {c.name: c.skillset for c in system.components}
    several = len(args.formulas) > 1
    formulas = [parse_formula(text, skillsets, f"<formula {n}>" if several else "<formula>")  # before exploring
                for n, text in enumerate(args.formulas, 1)]
    space = explore(system, marking, max_depth=args.max_depth, event_seeds=not args.no_seeds,
                    memory_limit=memory_limit(args), properties=len(formulas), deadline=Deadline.after(args.budget))
    kripke = Kripke(space)
    start = space.code(marking)
    results = []
    for text, formula in zip(args.formulas, formulas):
        t0 = time.perf_counter()
        result = check(kripke, formula)
        elapsed = time.perf_counter() - t0
        if start is not None and result.lower[start]:
            verdict = "holds"
        elif start is not None and not result.upper[start]:
            verdict = "fails"
        else:
            verdict = "undecided"
        results.append({
            "formula": text, "markings": space.markings, "satisfying": int(result.lower.sum()),
            "undecided": int((result.upper & ~result.lower).sum()), "start": verdict, "complete": kripke.truncated_by is None,
            "truncated_by": kripke.truncated_by, "elapsed": elapsed,
        })
    if args.json:
        _emit(results)
        return 0
    for n, r in enumerate(results):
        if n:
            print()
        print(f"formula: {r['formula']}")
        print(f"satisfied by {r['satisfying']} of {r['markings']} markings"
              + (f" ({r['undecided']} undecided)" if r["undecided"] else ""))
        print(f"at the start marking: {r['start']}")
    if kripke.truncated_by is not None:
        print(f"truncated by {kripke.truncated_by} ({space.explored()}): answers are three-valued")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
