"""Planning (issue 23, item 5): ``skinet plan``'s two engines beside Fast Downward, in one run.

Systems and goals (each goal involves every component of its system):

- the paper's system from arm at RD (``skillsets/states/arm_at_RD.json``):
  ``run spot:go_to_waypoint``, whose plan must bring the arm home first;
- the mobile manipulator from its initial marking: ``run arm:place`` (pick, then
  place, never while the base moves);
- N + N renamed corpus copies (N = 1..5) from the initial marking: every Spot
  standing and every arm moved once by hand (``arm_moving_manual``, so at Static).

Ours: the explicit and the symbolic engine, each in a fresh process: the first
plan (cold: arena, explored graph or BDDs built) and the median of repeated
plans on the same planner (warm: what the pilot pays at each marking change
from a marking already seen), CPU time of the thread; peak resident size of the
process (``VmHWM``).  Budget 10 s and memory limit 1 GiB.

Fast Downward (``unified-planning`` + ``up-fast-downward``, ``pip install -e
'.[bench]'``), in a fresh process: the same reachability question made
classical by letting the planner choose every outcome (all-outcomes
determinization): one action per (component, local state, move, result), each
with the component's local state as precondition and, as a further
precondition, that its result is not forced for any property (forced markings
excluded, docs/semantics.md §6.3; "the result is safe" is written as "each other component
in a state compatible with it", a positive disjunction: negative literals over
a one-hot group make Fast Downward's translator enumerate every combination of
the other values, and it did not finish 1 + 1 in 300 s).  Time:
``OneshotPlanner.solve`` wall seconds (translate and search are subprocesses);
memory: the largest peak resident size of those subprocesses (``VmHWM``,
sampled every 5 ms), beside the peak of the Python process that encodes; its
address space is capped (``--fd-memory``, 4 GiB: on 5 + 5 the search grew past
19 GiB before its timeout).

Then every plan is played 1 000 times against random outcomes (each enabled
outcome equally likely while a plan waits; each result of a command equally
likely): SkiNet's policy in closed loop, Fast Downward's plan as the open-loop
sequence it is (an outcome step waits for whatever comes; a command that is not
enabled any more is stuck).  Counted: plays that reach the goal, that violate
a property, that get stuck, and (ours, cyclic plans) that are still retrying
after 400 moves.

Targets: the paper's system, a plan in <= 5 ms warm in-process; 3 + 3, a goal
over all six components answered within 10 s and 1 GiB where the explicit
engine is cut by its budget.

    python benchmarks/bench_plan.py [--only paper,mobile,1,2,3,4,5] [--planners explicit,symbolic,fd]
        [--runs 1000] [--fd-timeout 300] [--fd-memory 4]       # about 30 min, most of it Fast Downward's timeouts
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from common import ROOT, copies_system, pin_one_core, table, verdict

GiB = 1 << 30
BUDGET = 10.0
TARGET = {"target": {"x": 12.0, "y": 3.5, "z": 0.0}}


def case(name: str) -> tuple[Any, dict[str, int], Any]:
    """(system, start marking, goal) of a case."""
    from skinet.system.load import load_state, load_system
    from skinet.plan import parse_goal

    if name == "paper":
        system, _ = load_system(ROOT / "skillsets" / "spot_arm.toml")
        start = load_state(ROOT / "skillsets" / "states" / "arm_at_RD.json", system)
        return system, start, parse_goal(system, "run spot:go_to_waypoint", {"go_to_waypoint": TARGET})
    if name == "mobile":
        system, _ = load_system(ROOT / "skillsets" / "mobile_manip.toml")
        return system, system.initial_marking(), parse_goal(system, "run arm:place")
    n = int(name)
    system = copies_system(n, n)
    spots = [c.name for c in system.components if c.name.startswith("spot")]
    arms = [c.name for c in system.components if c.name.startswith("manipulator")]
    text = "reach " + " and ".join([f"{s}:Standing" for s in spots] + [f"{a}:Static" for a in arms])
    inputs = {f"{a}:arm_moving_manual": {"target": {}} for a in arms}
    inputs.update({f"{s}:{k}": {"target": {}} for s in spots for k in ("go_to_body", "go_to_waypoint", "go_to_odom")})
    inputs.update({f"{a}:arm_moving_goaldriven": {"target": {}} for a in arms})
    return system, system.initial_marking(), parse_goal(system, text, inputs)


# -- playing plans against random outcomes -----------------------------------------------------


def play(arena: Any, goal: Any, start: tuple, next_step: Any, rng: random.Random, limit: int = 400) -> str:
    """One play: ``next_step(local, n)`` gives ("command", component, name), ("wait",),
    ("reached",) or ("end",); outcomes and results are drawn from ``rng``."""
    local = start
    for n in range(limit):
        if not arena.safe_at(local) and any(_violated(arena, local)):
            return "violation"
        step = next_step(local, n)
        if step[0] == "reached":
            return "reached"
        if step[0] == "end":
            return "reached" if goal.kind == "reach" and goal.holds(arena.system, arena.marking(local)) else "stuck"
        if step[0] == "command":
            i, name = step[1], step[2]
            move = next((mv for mv in arena.games[i].commands[local[i]] if mv.name == name), None)
            if move is None:
                return "stuck"
            local = local[:i] + (rng.choice(move.results),) + local[i + 1:]
        else:
            enabled = [(i, mv) for i, g in enumerate(arena.games) for mv in g.outcomes[local[i]]]
            if not enabled:
                return "stuck"
            i, mv = rng.choice(enabled)
            if goal.kind == "run" and goal.target(arena.names[i], mv.name):
                return "reached"
            local = local[:i] + (rng.choice(mv.results),) + local[i + 1:]
    return "retrying"


def _violated(arena: Any, local: tuple) -> list[str]:
    from skinet.props.evaluate import holds

    marking = arena.marking(local)
    return [p.name for p in arena.system.properties if not holds(p.expr, marking, arena.system.nets)]


def tally(outcomes: list[str]) -> dict[str, int]:
    return {k: outcomes.count(k) for k in ("reached", "violation", "stuck", "retrying")}


def play_ours(plan: Any, runs: int) -> dict[str, int]:
    from skinet.plan import Command, Reached, Wait

    arena = plan.arena

    def step(local: tuple, n: int) -> tuple:
        action = plan.action(arena.marking(local))
        if isinstance(action, Reached):
            return ("reached",)
        if isinstance(action, Command):
            return ("command", arena.names.index(action.skillset), action.transition)
        if isinstance(action, Wait):
            return ("wait",)
        return ("end",)

    rng = random.Random(23)
    return tally([play(arena, plan.goal, arena.root, step, rng) for _ in range(runs)])


def play_fd(arena: Any, goal: Any, steps: list[tuple[int, str, str]], runs: int) -> dict[str, int]:
    def step(local: tuple, n: int) -> tuple:
        if n >= len(steps):
            return ("end",)
        i, name, kind = steps[n]
        return ("command", i, name) if kind in ("start", "interrupt") else ("wait",)

    rng = random.Random(23)
    return tally([play(arena, goal, arena.root, step, rng, limit=len(steps) + 1) for _ in range(runs)])


# -- Fast Downward --------------------------------------------------------------------------------


def fd_problem(arena: Any, goal: Any) -> tuple[Any, dict[str, tuple[int, str, str]]]:
    """The all-outcomes determinization of the game, forced markings excluded."""
    from unified_planning.shortcuts import And, Fluent, InstantaneousAction, Not, Or, Problem

    from skinet.props.evaluate import evaluate

    at = {(i, s): Fluent(f"at_{i}_{s}") for i, g in enumerate(arena.games) for s in range(g.size)}
    done = Fluent("done")
    problem = Problem("skinet")
    for f in [*at.values(), done]:
        problem.add_fluent(f, default_initial_value=False)
    for i, s in enumerate(arena.root):
        problem.set_initial_value(at[(i, s)], True)
    boxes = [box for per in arena.forced.values() for box in per]
    allowed = arena.enabled(goal)
    names: dict[str, tuple[int, str, str]] = {}
    for i, g in enumerate(arena.games):
        for a in range(g.size):
            for mv in g.commands[a] + g.outcomes[a]:
                if mv.kind in ("start", "interrupt") and not allowed[i][g.command_names.index(mv.name)]:
                    continue
                for r in mv.results:
                    conditions = [at[(i, a)]]
                    dropped = False
                    bad: dict[int, set[int]] = {}  # boxes of two components: the other's states that are forced with r
                    for box in boxes:
                        mine = dict(box)
                        if i not in mine or not mine[i][r]:
                            continue
                        others = [(j, m) for j, m in box if j != i]
                        if not others:
                            dropped = True
                            break
                        if len(others) == 1:
                            j, m = others[0]
                            bad.setdefault(j, set()).update(s for s in range(len(m)) if m[s])
                        else:
                            inside = [Or(*[at[(j, s)] for s in range(len(m)) if m[s]]) for j, m in others]
                            conditions.append(Not(And(*inside)))
                    # Positive: the other component in a compatible state (negative literals over a one-hot
                    # group make the translator expand every combination of the other values).
                    for j, states in bad.items():
                        ok = [at[(j, s)] for s in range(arena.games[j].size) if s not in states]
                        if not ok:
                            dropped = True
                        conditions.append(Or(*ok) if ok else at[(j, 0)])
                    if dropped:
                        continue
                    name = f"c{i}_{mv.name.replace('.', '_')}_{a}_{r}"
                    action = InstantaneousAction(name)
                    action.add_precondition(And(*conditions))
                    if r != a:
                        action.add_effect(at[(i, a)], False)
                        action.add_effect(at[(i, r)], True)
                    if goal.kind == "run" and goal.target(arena.names[i], mv.name):
                        action.add_effect(done, True)
                    problem.add_action(action)
                    names[name] = (i, mv.name, mv.kind)
    if goal.kind == "run":
        problem.add_goal(done)
    else:
        def atom(a: Any) -> Any:
            i, mask = arena.atom(a)
            return Or(*[at[(i, s)] for s in range(len(mask)) if mask[s]])

        problem.add_goal(evaluate(goal.formula, atom, lambda v: v))
    return problem, names


class ChildPeak:
    """The largest peak resident size (``VmHWM``) of any descendant process, sampled every 5 ms.

    ``RUSAGE_CHILDREN`` would count the image of this process, which a child holds between
    fork and exec; a sampled child that has not exec'd yet (same command line) is skipped.
    """

    def __init__(self) -> None:
        import threading

        self.peak = 0
        self._stop = threading.Event()
        self._mine = Path("/proc/self/cmdline").read_bytes()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> "ChildPeak":
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        while not self._stop.wait(0.005):
            for pid in self._descendants(os.getpid()):
                try:
                    if Path(f"/proc/{pid}/cmdline").read_bytes() == self._mine:
                        continue
                    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                        if line.startswith("VmHWM:"):
                            self.peak = max(self.peak, int(line.split()[1]) * 1024)
                except OSError:
                    pass

    @staticmethod
    def _descendants(root: int) -> list[int]:
        parent: dict[int, int] = {}
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                try:
                    parent[int(entry)] = int(Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[1])
                except (OSError, IndexError, ValueError):
                    pass
        found, todo = [], [root]
        while todo:
            p = todo.pop()
            kids = [c for c, pp in parent.items() if pp == p]
            found += kids
            todo += kids
        return found


# -- one measurement in a fresh process -----------------------------------------------------------


def one(spec: dict[str, Any]) -> dict[str, Any]:
    from skinet.plan import Planner
    from skinet.verify.explore import peak_resident_bytes

    system, start, goal = case(spec["case"])
    if spec["who"] == "fd":
        import resource

        import unified_planning.shortcuts as ups

        limit = int(spec["fd_memory"])  # inherited by the translator and the search: on 5 + 5 the search
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))  # grew past 19 GiB before its timeout
        from unified_planning.engines import PlanGenerationResultStatus

        ups.get_environment().credits_stream = None
        arena = Planner(system).arena(start)
        t0 = time.perf_counter()
        problem, names = fd_problem(arena, goal)
        encode = time.perf_counter() - t0
        t0 = time.perf_counter()
        with ChildPeak() as children, ups.OneshotPlanner(name="fast-downward") as planner:
            result = planner.solve(problem, timeout=spec["fd_timeout"])
        wall = time.perf_counter() - t0
        solved = result.status in (PlanGenerationResultStatus.SOLVED_SATISFICING, PlanGenerationResultStatus.SOLVED_OPTIMALLY)
        steps = [names[a.action.name] for a in result.plan.actions] if solved else []
        plays = play_fd(arena, goal, steps, spec["runs"]) if solved else None
        status = result.status.name.lower()
        logs = " ".join(m.message for m in (result.log_messages or [])).lower()
        if not solved and ("memory" in logs or children.peak >= 0.95 * limit):
            status = f"out of memory at the {limit / GiB:.0f} GiB cap"  # what unified-planning reports as
            # unsolvable_incompletely: Fast Downward's exit for a search that ran out of memory
        return {"status": status, "length": len(steps), "time": wall, "encode": encode,
                "actions": len(names), "peak": children.peak, "self_peak": peak_resident_bytes(), "plays": plays}
    planner = Planner(system, spec["who"], memory_limit=GiB)
    c0 = time.thread_time()
    w0 = time.perf_counter()
    plan = planner.plan(goal, start, budget=BUDGET)
    cold, cold_wall = time.thread_time() - c0, time.perf_counter() - w0
    warm = []
    if plan.answer != "unknown":
        for _ in range(spec["repeats"]):
            c0 = time.thread_time()
            planner.plan(goal, start, budget=BUDGET)
            warm.append(time.thread_time() - c0)
    plays = play_ours(plan, spec["runs"]) if plan.answer in ("strong", "cyclic") else None
    return {"answer": plan.answer, "moves": plan.moves, "reason": plan.reason, "cold": cold, "cold_wall": cold_wall,
            "warm": statistics.median(warm) if warm else None, "markings": plan.stats.markings,
            "complete": plan.stats.complete, "truncated_by": plan.stats.truncated_by, "peak": peak_resident_bytes(),
            "plays": plays}


def fresh(spec: dict[str, Any], timeout: float) -> dict[str, Any]:
    try:
        proc = subprocess.run([sys.executable, __file__, "--one", json.dumps(spec)], capture_output=True, text=True,
                              timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return {"error": f"no answer in {timeout:.0f} s"}
    if proc.returncode:
        return {"error": (proc.stderr.strip().splitlines() or ["failed"])[-1][:120]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


# -- the report -----------------------------------------------------------------------------------


def ms(x: float | None) -> str:
    if x is None:
        return "-"
    return f"{x * 1000:.2f} ms" if x < 1 else f"{x:.2f} s"


def mib(x: int) -> str:
    return f"{x / 2**20:.0f} MiB"


def plays_text(p: dict[str, int] | None) -> str:
    if not p:
        return "-"
    text = f"{p['reached']} reached, {p['violation']} violation, {p['stuck']} stuck"
    return text + (f", {p['retrying']} retrying" if p.get("retrying") else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--only", default="paper,mobile,1,2,3,4,5")
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--fd-timeout", type=float, default=300.0)
    parser.add_argument("--fd-memory", type=float, default=4.0, help="address space of Fast Downward, GiB")
    parser.add_argument("--planners", default="explicit,symbolic,fd")
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one(json.loads(args.one))))
        return
    print(f"# bench_plan ({pin_one_core()}; load average {os.getloadavg()[0]:.1f})\n")
    rows = []
    results: dict[tuple[str, str], dict[str, Any]] = {}
    for name in args.only.split(","):
        label = name if name in ("paper", "mobile") else f"{name} + {name}"
        for who in args.planners.split(","):
            spec = {"case": name, "who": who, "runs": args.runs, "repeats": 50 if name in ("paper", "mobile", "1") else 5,
                    "fd_timeout": args.fd_timeout, "fd_memory": args.fd_memory * GiB}
            r = fresh(spec, args.fd_timeout + 120)
            results[(name, who)] = r
            if "error" in r:
                rows.append([label, who, r["error"], "-", "-", "-", "-"])
            elif who == "fd":
                rows.append([label, "Fast Downward", f"{r['status']}, {r['length']} actions" if r["length"] else r["status"],
                             ms(r["time"]) + f" (+ {ms(r['encode'])} to encode {r['actions']} actions)", "-",
                             mib(r["peak"]) + f" (search; ours {mib(r['self_peak'])})", plays_text(r["plays"])])
            else:
                state = "complete" if r["complete"] else f"cut by {r['truncated_by']}"
                answer = f"{r['answer']}" + (f", {r['moves']} moves" if r["moves"] is not None else "")
                rows.append([label, f"{who} ({r['markings']} markings, {state})", answer, ms(r["cold_wall"]),
                             ms(r["warm"]), mib(r["peak"]), plays_text(r["plays"])])
            print(" | ".join(str(c) for c in rows[-1]), file=sys.stderr, flush=True)
    print(table(["system", "planner", "answer", "first plan (wall)", "warm (CPU, median)", "peak memory",
                 f"{args.runs} plays against random outcomes"], rows))
    print()
    targets = []
    paper = results.get(("paper", "explicit"))
    if paper and "error" not in paper and paper["warm"] is not None:
        targets.append(["paper's system: a plan <= 5 ms warm in-process", ms(paper["warm"]), verdict(paper["warm"] <= 0.005)])
    sym, exp = results.get(("3", "symbolic")), results.get(("3", "explicit"))
    if sym and exp and "error" not in sym and "error" not in exp:
        ok = sym["answer"] in ("strong", "cyclic", "none") and sym["cold_wall"] <= 10 and sym["peak"] <= GiB
        cut = exp["answer"] == "unknown"
        targets.append(["3 + 3: goal over six components within 10 s and 1 GiB",
                        f"symbolic {sym['answer']} in {ms(sym['cold_wall'])}, {mib(sym['peak'])}; explicit "
                        f"{exp['answer']} ({'cut by ' + str(exp['truncated_by']) if cut else 'complete'})",
                        verdict(ok and cut)])
    safe = all(r["plays"]["violation"] == 0 and r["plays"]["stuck"] == 0
               for (n, who), r in results.items() if who != "fd" and "error" not in r and r.get("plays"))
    targets.append(["no SkiNet play violates a property or gets stuck", "yes" if safe else "NO", verdict(safe)])
    print(table(["target", "measured", "verdict"], targets))


if __name__ == "__main__":
    main()
