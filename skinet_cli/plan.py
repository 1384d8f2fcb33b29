"""``skinet plan``: commands that reach a goal and never violate a property (docs/semantics.md §8)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from chains.pilot_lines import moves_text, toml_value
from skinet.errors import Pos, SkinetError, SourceError
from skinet.system.load import load_goals, load_typemap
from skinet.plan.goal import Goal, parse_goal
from skinet.plan.inputs import Inputs, parse_inputs
from skinet.plan.planner import ENGINES, Planner
from skinet.plan.policy import Branch, Command, Plan, Reached, Step, Wait
from skinet.system.model import System, marking_problems, marking_to_json
from skinet.files.toml import parse_toml

if TYPE_CHECKING:  # pydantic only for the types: `skinet plan` does not import it
    from skinet.wire.messages import PlanBranch, PlanStep
from services.common.memory import add_memory_arg, memory_limit
from services.common.options import load_live_system, print_warnings, state_marking
from services.common.options import seconds as duration, time_budget
from chains.render import seconds

HELP = "plan the commands that reach a goal without violating any property (docs/semantics.md §8)"
DESCRIPTION = """\
Plans the commands that reach each goal from the start marking while no
property can be violated, whatever the skills' outcomes: only commands after
which no outcome can lead to a violation (the markings SkiNet calls forced).
Answers strong (reached whatever the outcomes, in at most N moves), cyclic
(reached if retries eventually succeed; N moves when outcomes are
favourable), none (with the reason) or unknown (the budget or the memory
limit cut the search). Several goals (or a --goals file) form a mission:
each is planned from where the previous one's favourable path ends."""
EPILOG = """\
goals:
  reach FORMULA                      a marking where FORMULA holds (the property language)
  run SKILLSET:SKILL                 start SKILL and have it end in a success mode
  run SKILLSET:SKILL.success.MODE    ... in that success mode

examples:
  skinet plan skillsets/spot_arm.toml "reach spot:Standing and manipulator:RD"
  skinet plan skillsets/spot_arm.toml "run spot:go_to_waypoint" \\
      --inputs 'go_to_waypoint.target = {x = 12.0, y = 3.5, z = 0.0}'
  skinet plan skillsets/spot_arm.toml --goals skillsets/goals/walk.toml --json"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("plan", help=HELP, description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter, intermixed=True)  # goals after options too
    c.add_argument("system", help="system file (.toml), e.g. skillsets/spot_arm.toml")
    add_goal_args(c)
    c.add_argument("--state", metavar="STATE",
                   help="start marking: a JSON file, or the JSON itself ('{\"spot\": {...}}'); omitted resources are "
                        "initial, omitted skills idle (default: the initial marking)")
    c.add_argument("--budget", type=time_budget(), default=10.0,
                   help="time budget per goal in seconds (default: 10); past it the answer is unknown")
    add_memory_arg(c)
    c.add_argument("--engine", choices=ENGINES, default="auto",
                   help="explicit (the explored graph), symbolic (BDDs of the whole product) or auto "
                        "(explicit for small products; default)")
    c.add_argument("--json", action="store_true", help="machine-readable plans (a list, one per goal)")
    c.set_defaults(func=cmd_plan)


def add_goal_args(c: argparse.ArgumentParser) -> None:
    """GOAL..., ``--goals FILE`` and ``--inputs TOML``, read by :func:`read_goals` (``skinet plan``, ``skinet goal``)."""
    c.add_argument("goals", nargs="*", metavar="GOAL",
                   help='a goal, e.g. "run spot:init_power" (several: a mission, in order; after --goals ones)')
    c.add_argument("--goals", dest="goals_file", metavar="FILE",
                   help="a mission: a TOML file of [[goals]] tables, each with reach = or run = and its inputs")
    c.add_argument("--inputs", metavar="TOML",
                   help="skill inputs of the GOAL arguments, as TOML: 'go_to_waypoint.target = {x = 1.0, y = 2.0, z = 0.0}' "
                        "(a skill name, or skillset:skill in quotes, then each input)")


def read_goals(args: argparse.Namespace, system: System) -> list[Goal]:
    """The goals of ``args.goals_file`` then of the GOAL arguments, with ``args.inputs`` (both ``skinet plan``
    and ``skinet goal``); :class:`SourceError` at the file, line and column of a bad one."""
    types = load_typemap(args.system)
    goals = load_goals(args.goals_file, system, types) if args.goals_file else []
    inputs: Inputs = {}
    if args.inputs is not None:
        from skinet.plan.goalfile import nested

        lines = args.inputs.splitlines()
        inputs = parse_inputs(system, parse_toml(args.inputs, "<--inputs>"), "<--inputs>",
                              lambda keys: nested(lines, Pos(1, 1), keys) if keys else None, types)
    several = len(args.goals) > 1
    for n, text in enumerate(args.goals, 1):
        goals.append(parse_goal(system, text, inputs, f"<goal {n}>" if several else "<goal>", types=types,
                                given_with="flag"))
    if not goals:
        raise SkinetError("no goals: give GOAL arguments (e.g. \"reach spot:Standing\") or --goals FILE")
    if any(c.binding for c in system.components):  # a bound skill's inputs: what its goal message can hold
        from skinet.system.load import load_bindings
        from skinet.ros.binding import bound_inputs_problem

        bindings, _ = load_bindings(system)
        for goal in goals:
            for (skillset, skill), values in goal.inputs.items():
                problem = bound_inputs_problem(bindings, skillset, skill, values)
                if problem:
                    raise SkinetError(f"goal '{goal.text}': {problem}")
    return goals


def cmd_plan(args: argparse.Namespace) -> int:
    system, warnings = load_live_system(args.system)
    print_warnings(warnings)
    goals = read_goals(args, system)
    marking = system.initial_marking()
    if args.state:
        marking, source = state_marking(args.state, system, what_if=True)
        problems = marking_problems(system, marking)
        if problems:  # (no --what-if here: no plan starts where the robot cannot be)
            raise SourceError.at(source, None, "impossible state: " + "; ".join(problems))
    planner = Planner(system, args.engine, memory_limit(args))
    plans = planner.mission(goals, marking, args.budget)
    if args.json:
        out = [plan_json(system, p) for p in plans]
        out += [{"goal": g.text, "answer": "unknown", "moves": None,
                 "reason": f"not planned: goal {len(plans)} has no plan, so where this one starts is unknown",
                 "steps": [], "policy": [], "stats": None} for g in goals[len(plans):]]
        print(json.dumps(out, indent=2))
        return 0
    for n, plan in enumerate(plans, 1):
        if n > 1:
            print()
        head = f"goal {n}" if len(goals) > 1 else "goal"
        print(f"{head}: {plan.goal.text}" + (f" (from where goal {n - 1} ends)" if n > 1 else ""))
        print("\n".join(plan_lines(plan)))
    for n, goal in enumerate(goals[len(plans):], len(plans) + 1):
        print(f"\ngoal {n}: {goal.text}\nnot planned: goal {len(plans)} has no plan")
    return 0


def answer_line(plan: Plan) -> str:
    return answer_text(plan.answer, plan.moves, plan.retries, plan.reason)


def answer_text(answer: str, moves: int | None, retries: Sequence[str] = (), reason: str | None = None) -> str:
    """A plan's answer in one line (``skinet plan``, and ``skinet goal`` for the pilot's reply)."""
    if answer == "strong":
        return f"strong: at most {moves_text(moves or 0)}, whatever the outcomes"
    if answer == "cyclic":
        text = f"cyclic: {moves_text(moves or 0)} when outcomes are favourable"
        return text + (f"; retries after {', '.join(retries)}" if retries else "")
    return f"{answer}: {reason}" if reason else answer


def plan_lines(plan: Plan) -> list[str]:
    out = [answer_line(plan)]
    if plan.steps:
        out.append("steps:")
        out.extend(step_lines(plan.steps, "  "))
    s = plan.stats
    state = "complete" if s.complete else f"cut by the {'memory limit' if s.truncated_by == 'memory' else s.truncated_by}"
    out.append(f"{s.engine} engine: {s.markings} markings ({state}), {seconds(s.elapsed)}")
    return out


def step_lines(steps: Sequence[Step | PlanStep], indent: str) -> list[str]:
    """Numbered steps with their branches, indented (a plan's, or the pilot's :class:`PlanStep` copies)."""
    out = []
    for step in steps:
        head = f"{indent}{step.number}. "
        if step.action == "wait":
            out.append(f"{head}wait for {step.skillset}:{step.expect}")
        else:
            given = f" with {toml_value(step.inputs)}" if step.inputs else ""
            out.append(f"{head}{step.skillset}:{step.action}{given}")
        for b in step.branches:
            out.extend(_branch_lines(b, " " * len(head)))
    return out


def _branch_lines(b: Branch | PlanBranch, indent: str) -> list[str]:
    label = f"{indent}if {b.skillset}:{b.transition}"
    if b.then == "retry":
        return [f"{label}: retry from step {b.step}"]
    if b.then == "continue":
        return [f"{label}: continue at step {b.step}"]
    if b.then == "reached":
        return [f"{label}: the goal is reached"]
    lines = [f"{label}:"] + step_lines(b.steps, indent + "  ")
    if b.step is not None:
        lines.append(f"{indent}  then continue at step {b.step}")
    return lines


def plan_json(system: System, plan: Plan) -> dict[str, Any]:
    policy, whole = plan.policy()
    end = plan.end
    return {
        "goal": plan.goal.text,
        "answer": plan.answer,
        "moves": plan.moves,
        "reason": plan.reason,
        "retries": plan.retries,
        "recovery": [{"skillset": c, "action": t} for c, t in plan.recovery],
        "steps": [_step_json(s) for s in plan.steps],
        "policy": [{"state": marking_to_json(system, m), "action": _action_json(a), "rank": r} for m, a, r in policy],
        "policy_complete": whole,
        "start": marking_to_json(system, plan.arena.marking(plan.start)),
        "end": None if end is None else marking_to_json(system, end),
        "stats": {"markings": plan.stats.markings, "time": plan.stats.elapsed, "engine": plan.stats.engine,
                  "complete": plan.stats.complete, "truncated_by": plan.stats.truncated_by},
    }


def _action_json(action: Command | Wait | Reached) -> dict[str, Any] | None:
    if isinstance(action, Command):
        return {"skillset": action.skillset, "action": action.transition, "inputs": dict(action.inputs) or None}
    if isinstance(action, Wait):
        return {"skillset": None, "action": "wait", "inputs": None}
    return None  # the goal holds: nothing to do


def _step_json(step: Step) -> dict[str, Any]:
    return {"number": step.number, "skillset": step.skillset, "action": step.action, "expect": step.expect,
            "inputs": dict(step.inputs) if step.inputs else None,
            "branches": [{"skillset": b.skillset, "transition": b.transition, "then": b.then, "step": b.step,
                          "steps": [_step_json(s) for s in b.steps]} for b in step.branches]}
