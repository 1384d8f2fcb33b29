"""The ``skinet`` command line: a thin shell over the core library."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from skinet import __version__
from skinet.errors import SkinetError, SourceError
from skinet.files import load_model, load_state, load_system
from skinet.lang.expr import to_text
from skinet.net.build import build_net
from skinet.net.export import FORMATS
from skinet.props.parser import parse_formula
from skinet.system import System, marking_problems, marking_to_json
from skinet.verify.algorithm1 import analyse
from skinet.verify.ctl import Kripke, check
from skinet.verify.explore import explore
from skinet.verify.predict import Forecast, forecast
from skinet.cli import demo
from skinet.cli import record as record_cli
from skinet.cli import timeline as timeline_cli
from skinet.cli.render import analysis_text, seconds, table
from skinet.cli.run import add_commands as add_service_commands

DESCRIPTION = """\
SkiNet Live: predictive runtime verification of skill-based robots.
Turns ONERA robot-language skillsets (.rl) into Petri nets, checks safety
properties and reports the commands and events that would violate them now
(explicit constraints), inevitably later (implicit constraints: AF not phi,
fair by default) or through skill outcomes no command can prevent (forced
constraints)."""

EPILOG = """\
examples:
  skinet demo
  skinet parse skillsets/spot.rl
  skinet net skillsets/spot.rl --eventless --format tina -o spot.net
  skinet unsafe skillsets/spot_arm.toml --state state.json
  skinet explore skillsets/spot_arm.toml --budget 2
  skinet ctl skillsets/spot_arm.toml "AG not (spot:Busy and manipulator:Busy)"
  skinet run skillsets/spot_arm.toml --listen tcp/127.0.0.1:7447
  skinet router --listen tcp/0.0.0.0:7447

state files (--state) are JSON: {"spot": {"resources": {"posture": "Standing"},
"running": ["teleop"]}}; omitted resources are initial, omitted skills idle."""


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except SourceError as exc:
        print(str(exc), file=sys.stderr)
        return 1
    except SkinetError as exc:
        print(f"skinet: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("skinet: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="skinet", description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--version", action="version", version=f"skinet {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    c = sub.add_parser("parse", help="check a .rl skillset file and summarise it")
    c.add_argument("file", help="skillset model (.rl)")
    c.add_argument("--json", action="store_true", help="machine-readable summary")
    c.set_defaults(func=cmd_parse)

    c = sub.add_parser("net", help="print the Petri net of a skillset (SPEC §3)")
    c.add_argument("file", help="skillset model (.rl)")
    c.add_argument("--eventless", action="store_true", help="the eventless net SkN^e (no event transitions)")
    c.add_argument("--format", choices=sorted(FORMATS), default="json", help="output format (default: json)")
    c.add_argument("-o", "--output", help="write to this file instead of standard output")
    c.set_defaults(func=cmd_net)

    c = sub.add_parser("unsafe", help="Algorithm 1: unsafe transitions at a marking (SPEC §5)")
    _system_args(c)
    c.add_argument("--no-predict", action="store_true", help="explicit constraints only (mu1 empty)")
    c.add_argument("--literal", action="store_true", help="also list transitions flagged for properties already violated")
    c.set_defaults(func=cmd_unsafe)

    c = sub.add_parser("explore", help="explore the eventless state space and compute mu1 (SPEC §6)")
    _system_args(c)
    c.add_argument("--progress", action="store_true", help="print progress per layer on standard error")
    c.set_defaults(func=cmd_explore)

    c = sub.add_parser("ctl", help="model-check a CTL formula on the explored state space")
    _system_args(c)
    c.add_argument("formula", help='e.g. "AG not (spot:Busy and manipulator:Busy)"')
    c.set_defaults(func=cmd_ctl)

    demo.add_parser(sub)
    record_cli.add_parser(sub)
    timeline_cli.add_parser(sub)
    add_service_commands(sub)
    return p


def _system_args(c: argparse.ArgumentParser) -> None:
    c.add_argument("system", help="system file (.toml), e.g. skillsets/spot_arm.toml")
    c.add_argument("--state", help="start marking as JSON (default: initial marking)")
    c.add_argument(
        "--what-if", action="store_true",
        help="accept a --state the robot cannot be in (an invariant violated, or unreachable) for what-if analysis",
    )
    c.add_argument("--budget", type=float, default=10.0, help="exploration time budget in seconds (default: 10)")
    c.add_argument("--max-depth", type=int, help="expand at most this many breadth-first layers")
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
    system, warnings = load_system(args.system)
    for w in warnings:
        print(str(w), file=sys.stderr)
    system = replace(system, prediction=system.prediction.override(
        af=args.af, forced=args.forced, events_uncontrollable=args.events_uncontrollable))
    marking = load_state(args.state, system, args.what_if) if args.state else system.initial_marking()
    for problem in marking_problems(system, marking) if args.what_if else ():
        print(f"what-if analysis: {problem}", file=sys.stderr if args.json else sys.stdout)
    return system, marking


def _forecast(args: argparse.Namespace, system: System, marking: dict[str, int], full: bool = False) -> Forecast:
    show = getattr(args, "progress", False) or (sys.stderr.isatty() and not args.json)
    last = [0.0]

    def progress(depth: int, markings: int, elapsed: float) -> None:
        if show and elapsed - last[0] >= 0.2:
            last[0] = elapsed
            print(f"\r  layer {depth}: {markings} markings, {seconds(elapsed)}", end="", file=sys.stderr, flush=True)

    result = forecast(
        system, marking, budget=args.budget, max_depth=args.max_depth, event_seeds=not args.no_seeds, progress=progress,
        full=full,
    )
    if last[0] > 0:
        print(file=sys.stderr)
    return result


def _emit(data: object) -> None:
    print(json.dumps(data, indent=2))


def cmd_parse(args: argparse.Namespace) -> int:
    model = load_model(args.file)
    for w in model.warnings:
        print(str(w), file=sys.stderr)
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
    model = load_model(args.file)
    for w in model.warnings:
        print(str(w), file=sys.stderr)
    nets = [build_net(s, eventless=args.eventless) for s in model.skillsets]
    if len(nets) > 1:
        from skinet.net.union import union

        nets = [union(nets, Path(args.file).stem)]
    text = FORMATS[args.format](nets[0])
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
            "unsafe": [u.__dict__ | {"witness": list(u.witness)} for u in (result.unsafe if args.literal else result.operator_unsafe())],
            "options": {p.name: system.prediction.of(p.name).__dict__ for p in system.properties},
            "recovery": {p: [r.__dict__ for r in rs] for p, rs in result.recovery.items()},
            "prediction": None if prediction is None else prediction.report(),
        })
        return 0
    print(analysis_text(system, result, args.literal))
    if prediction is not None:
        r = prediction.report()
        state = "complete" if r["complete"] else f"TRUNCATED at depth {r['depth']} (unknown constraints possible)"
        print(f"prediction: {state}, {r['markings']} markings in {seconds(r['elapsed'])}")
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
        ["complete", "yes" if report["complete"] else "no (time budget or depth limit reached)"],
        ["elapsed", seconds(report["elapsed"])],
        ["depth", report["depth"]],
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
    formula = parse_formula(args.formula, {c.name: c.skillset for c in system.components})
    space = explore(system, marking, budget=args.budget, max_depth=args.max_depth, event_seeds=not args.no_seeds)
    kripke = Kripke(space)
    t0 = time.perf_counter()
    result = check(kripke, formula)
    elapsed = time.perf_counter() - t0
    start = space.code(marking)
    if start is not None and result.lower[start]:
        verdict = "holds"
    elif start is not None and not result.upper[start]:
        verdict = "fails"
    else:
        verdict = "undecided"
    holds = int(result.lower.sum())
    maybe = int((result.upper & ~result.lower).sum())
    if args.json:
        _emit({
            "formula": to_text(formula), "markings": space.markings, "satisfying": holds,
            "undecided": maybe, "start": verdict, "complete": space.complete, "elapsed": elapsed,
        })
        return 0
    print(f"formula: {args.formula}")
    print(f"satisfied by {holds} of {space.markings} markings" + (f" ({maybe} undecided)" if maybe else ""))
    print(f"at the start marking: {verdict}")
    if not space.complete:
        print(f"exploration truncated at depth {space.expanded_depth}: answers are three-valued")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
