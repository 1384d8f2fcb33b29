"""Issue 31, item 1: ``skinet ctl --budget B`` bounds every formula, however deeply nested.

What ``skinet ctl --budget B --max-depth 8 --no-seeds`` does on 5 Spot + 5 arm
corpus copies (2.0 M markings explored in about 0.3 s, so the fixpoints meet
the deadline): one deadline for the exploration, the successor structure and
the check.  For each operator, a chain nested 1, 10, 30 and 40 deep; the
baseline, measured in the same run, is the chain 1 deep: the time a deeper
formula spends past the deadline must not exceed the 1-deep one's by more than
0.25 s (and the wall must stay <= B + 1 s).  Before the fix, A[U] 30 deep took 14.0 s with
B = 2 and 4.6 s with B = 0.5 (each outer operator ran its degree pass over
every stored marking, twice).  About a minute.  Cost: one exploration per row.
"""

from __future__ import annotations

import argparse
import time

from common import copies_system, pin_one_core  # also puts the repository on sys.path

from skinet.lang.expr import Expr, Not  # noqa: E402
from skinet.props.formula import PlaceAtom, Temporal, Until  # noqa: E402
from skinet.verify.ctl import Kripke, check  # noqa: E402
from skinet.verify.explore import Deadline, explore  # noqa: E402

OPS = ("AU", "AF", "EU", "EG", "AG", "AX")
DEPTHS = (1, 10, 30, 40)


def chain(op: str, atom: Expr, other: Expr, depth: int) -> Expr:
    f = atom
    for _ in range(depth):
        f = Until(op[0], other, f) if op in ("AU", "EU") else Temporal(op, f)
    return f


def run(system, marking, formula: Expr, budget: float) -> tuple[float, str, int]:  # type: ignore[no-untyped-def]
    t0 = time.perf_counter()
    space = explore(system, marking, max_depth=8, event_seeds=False, memory_limit=None, properties=1,
                    deadline=Deadline.after(budget))
    k = Kripke(space)
    r = check(k, formula)
    start = space.code(marking)
    assert start is not None
    verdict = "holds" if r.lower[start] else "fails" if not r.upper[start] else "undecided"
    int(r.lower.sum()), int((r.upper & ~r.lower).sum())  # the counts skinet ctl prints
    return time.perf_counter() - t0, verdict, space.markings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budgets", type=float, nargs="+", default=[0.5, 2.0])
    args = parser.parse_args()
    print(f"<!-- {pin_one_core()} -->")
    system = copies_system(5, 5)
    marking = system.initial_marking()
    g = explore(system, marking, max_depth=0, event_seeds=False).components  # the places' nets
    p, q = PlaceAtom(g[0].name, g[0].net.places[0]), Not(PlaceAtom(g[-1].name, g[-1].net.places[0]))
    print("| operator | budget | depth | markings | wall | past the budget | 1 deep: past (baseline) | start | |")
    print("|---|---|---|---|---|---|---|---|---|")
    misses = 0
    for budget in args.budgets:
        for op in OPS:
            base = None
            for depth in DEPTHS:
                wall, verdict, markings = run(system, marking, chain(op, p, q, depth), budget)
                past = max(0.0, wall - budget)
                base = past if base is None else base
                ok = wall <= budget + 1 and past <= base + 0.25
                misses += not ok
                print(f"| {op} | {budget:g} s | {depth} | {markings} | {wall:.2f} s | {past:.2f} s | {base:.2f} s "
                      f"| {verdict} | {'PASS' if ok else 'MISS'} |", flush=True)
    print(f"\n{misses} MISS")


if __name__ == "__main__":
    main()
