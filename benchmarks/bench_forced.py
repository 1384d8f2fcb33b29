"""Issue 9 benchmark: forced verdicts and fair AF, beside the current Algorithm 1 cost.

(1) 4 copies of the corpus spot + 4 of the corpus manipulator (action_guard and
safety_guard for each spot/arm pair: 8 properties), at live markings reached by
a seeded random walk (several skills running): every forced verdict of every
one-step successor, cold (nothing memoised) and warm, beside Algorithm 1 with
explicit constraints only and Algorithm 1 with forced constraints, measured in
the same run.  Target: all forced verdicts <= 5 ms in-process.

Times are CPU time of the measuring thread (medians), so that other work on
the machine does not inflate them.

(2) The paper's system: complete exploration + mu1 with fair AF beside literal
AF, measured in the same run.  Target: <= 2 ms (docs/semantics.md §6.2 keeps (a) of
bench_paper.py).

    python benchmarks/bench_forced.py [--markings N] [--repeats N]
"""

from __future__ import annotations

import argparse
import random

import time
from collections.abc import Callable

from common import CORPUS, _copies, median_time, paper_system, pin_one_core, table, verdict

from skinet.net.semantics import steps
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.system.model import Marking, System, build_system
from skinet.verify.algorithm1 import analyse
from skinet.verify.component import forget_component_graphs
from skinet.verify.forced import oracle
from skinet.verify.predict import forecast

EXPLICIT_ONLY = PredictionOptions(PropertyOptions(forced=False))
LITERAL = PredictionOptions(PropertyOptions(af="literal"))


def cpu_time(fn: Callable[[], object], repeats: int, before: Callable[[], None] | None = None) -> float:
    return median_time(fn, repeats, before, clock=time.thread_time)


def fleet(n: int) -> System:
    """``n`` corpus spots and ``n`` corpus arms; the corpus properties for each pair."""
    skillsets = _copies("spot.rl", "spot", n) + _copies("manipulator.rl", "manipulator", n)
    text = (CORPUS / "spot_manipulator.props").read_text()
    props = []
    for k in range(1, n + 1):
        suffix = "" if k == 1 else str(k)
        for line in text.splitlines():
            if "=" in line and not line.lstrip().startswith("#"):
                name, expr = line.split("=", 1)
                expr = expr.replace("spot:", f"spot{suffix}:").replace("manipulator:", f"manipulator{suffix}:")
                props.append(f"{name.strip()}{suffix} = {expr.strip()}")
    return build_system(f"{n}spot+{n}arm", [(s, "") for s in skillsets], "\n".join(props))


def walk(system: System, seed: int, length: int = 40) -> Marking:
    """A live marking after ``length`` random steps of the full nets (commands, outcomes, events)."""
    rng = random.Random(seed)
    marking = system.initial_marking()
    for _ in range(length):
        comp = rng.choice(system.components)
        options = steps(comp.net, marking[comp.name])
        if options:
            _t, results = rng.choice(options)
            marking[comp.name] = rng.choice(sorted(results))
    return marking


def successors(system: System, marking: Marking) -> list[Marking]:
    out = []
    for comp in system.components:
        for _t, results in steps(comp.net, marking[comp.name]):
            for m in results:
                after = dict(marking)
                after[comp.name] = m
                out.append(after)
    return out


def all_forced(system: System, marking: Marking) -> int:
    """Every forced verdict of every one-step successor; returns how many are forced."""
    ora = oracle(system)
    return sum(ora.verdict(p, after) is not None for after in successors(system, marking) for p in system.properties)


def forget_forced(system: System) -> None:
    system.__dict__.pop("_forced_oracles", None)
    for c in system.components:
        c.net.__dict__.pop("_unc_reach", None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--markings", type=int, default=5, help="live markings of the 4+4 system (default 5)")
    ap.add_argument("--repeats", type=int, default=21, help="timed repeats per figure (default 21)")
    args = ap.parse_args()
    print(f"# Issue 9: forced verdicts and fair AF ({pin_one_core()})\n")

    system = fleet(4)
    rows = []
    worst_cold = 0.0
    for seed in range(args.markings):
        m = walk(system, seed)
        running = sum(bin(m[c.name]).count("1") for c in system.components)  # places marked, for the record
        n_succ = len(successors(system, m))
        explicit = cpu_time(lambda: analyse(system, m, options=EXPLICIT_ONLY), args.repeats)
        with_forced = cpu_time(lambda: analyse(system, m), args.repeats, before=lambda: forget_forced(system))
        cold = cpu_time(lambda: all_forced(system, m), args.repeats, before=lambda: forget_forced(system))
        all_forced(system, m)
        warm = cpu_time(lambda: all_forced(system, m), args.repeats)
        worst_cold = max(worst_cold, cold)
        rows.append([seed, n_succ, all_forced(system, m), f"{explicit * 1e3:.2f}", f"{with_forced * 1e3:.2f}",
                     f"{cold * 1e3:.2f}", f"{warm * 1e3:.3f}", running])
    print("## (1) 4 corpus spots + 4 corpus arms, 8 properties: forced verdicts of every one-step successor\n")
    print(table(["walk seed", "successors", "forced (succ x prop)", "Algorithm 1 explicit only (ms)",
                 "Algorithm 1 + forced, cold (ms)", "all forced verdicts, cold (ms)", "warm (ms)", "places marked"],
                rows))
    print(f"\nTarget <= 5 ms (cold, worst marking): {worst_cold * 1e3:.2f} ms -> {verdict(worst_cold <= 0.005)}\n")

    paper = paper_system()
    forecast(paper)  # imports and first numpy calls outside the timed region
    cold_graphs = lambda: [forget_component_graphs(c.eventless) for c in paper.components]  # noqa: E731
    fair = cpu_time(lambda: forecast(paper), 200)
    literal = cpu_time(lambda: forecast(paper, options=LITERAL), 200)
    fair_cold = cpu_time(lambda: forecast(paper), 100, before=cold_graphs)
    literal_cold = cpu_time(lambda: forecast(paper, options=LITERAL), 100, before=cold_graphs)
    print("## (2) paper system: complete exploration + mu1, fair AF beside literal AF\n")
    print(table(["AF", "warm (ms)", "component graphs rebuilt (ms)", "target", "verdict"], [
        ["fair (operator default)", f"{fair * 1e3:.2f}", f"{fair_cold * 1e3:.2f}", "2 ms", verdict(fair <= 0.002)],
        ["literal (the paper's)", f"{literal * 1e3:.2f}", f"{literal_cold * 1e3:.2f}", "2 ms", verdict(literal <= 0.002)],
    ]))


if __name__ == "__main__":
    main()
