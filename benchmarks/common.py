"""Shared helpers of the benchmarks: systems, the pure-Python baseline, tables.

The baseline is the straightforward search docs/semantics.md §6 compares against: a
breadth-first search over combined markings (tuples of per-skillset bit
masks), firing each component's eventless net with
:func:`skinet.net.semantics.steps` at every marking; no numpy, no product
trick, no memoisation.
"""

from __future__ import annotations

import os
import re
import statistics
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import product
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from skinet.lang.model import Skillset  # noqa: E402
from skinet.lang.parser import parse_skillset  # noqa: E402
from skinet.net.semantics import stabilize, steps  # noqa: E402
from skinet.props.evaluate import holds  # noqa: E402
from skinet.system.model import System, build_system  # noqa: E402
from skinet.verify.component import forget_component_graphs  # noqa: E402

CORPUS = ROOT.parent / "shared" / "corpus"
PAPER = ROOT / "skillsets"
Combined = tuple[int, ...]


def pin_one_core() -> str:
    """Run on CPU 0 only, where the OS allows it."""
    try:
        os.sched_setaffinity(0, {0})
        return "pinned to CPU 0"
    except (AttributeError, OSError) as exc:
        return f"not pinned ({exc.__class__.__name__})"


def paper_system() -> System:
    """The seed paper's Spot + Kinova system (skillsets/)."""
    skillsets = [parse_skillset((PAPER / f).read_text(), str(PAPER / f)) for f in ("spot.rl", "manipulator.rl")]
    return build_system("spot_arm", [(s, "") for s in skillsets], (PAPER / "spot_arm.props").read_text())


def _copies(file: str, name: str, n: int) -> list[Skillset]:
    text = (CORPUS / file).read_text()
    out = []
    for k in range(1, n + 1):
        renamed = name if k == 1 else f"{name}{k}"
        out.append(parse_skillset(re.sub(rf"skillset\s+{name}\b", f"skillset {renamed}", text, count=1), file))
    return out


def copies_system(n_spot: int, n_arm: int) -> System:
    """``n_spot`` copies of corpus spot.rl and ``n_arm`` of manipulator.rl (spot, spot2, ...)."""
    skillsets = _copies("spot.rl", "spot", n_spot) + _copies("manipulator.rl", "manipulator", n_arm)
    props = (CORPUS / "spot_manipulator.props").read_text()
    return build_system(f"{n_spot}spot+{n_arm}arm", [(s, "") for s in skillsets], props)


def forget(system: System) -> None:
    """Drop memoised component graphs, so the next exploration starts cold."""
    for c in system.components:
        forget_component_graphs(c.eventless)


@dataclass
class Baseline:
    markings: int
    edges: int
    seconds: float
    finished: bool
    succ: dict[Combined, set[Combined]]


def baseline_explore(system: System, event_seeds: bool = True, deadline: float = 60.0) -> Baseline:
    """Breadth-first search over combined markings; stops after ``deadline`` seconds."""
    t0 = time.perf_counter()
    comps = system.components
    initial = tuple(c.net.initial for c in comps)
    roots = list(product(*(sorted(stabilize(c.eventless, m)) for c, m in zip(comps, initial))))
    sources = set(roots)
    if event_seeds:
        for i, c in enumerate(comps):
            for t, results in steps(c.net, initial[i]):
                if t.kind == "event":
                    sources |= {r[:i] + (m,) + r[i + 1:] for m in results for r in roots}
    seen = set(sources)
    succ: dict[Combined, set[Combined]] = {}
    queue = deque(sources)
    edges = 0
    while queue:
        if len(succ) % 1024 == 0 and time.perf_counter() - t0 > deadline:
            return Baseline(len(seen), edges, time.perf_counter() - t0, False, succ)
        m = queue.popleft()
        out = set()
        for i, c in enumerate(comps):
            for _, results in steps(c.eventless, m[i]):
                for r in results:
                    out.add(m[:i] + (r,) + m[i + 1:])
        succ[m] = out
        edges += len(out)
        for n in out:
            if n not in seen:
                seen.add(n)
                queue.append(n)
    return Baseline(len(seen), edges, time.perf_counter() - t0, True, succ)


def baseline_mu1(system: System, succ: dict[Combined, set[Combined]]) -> dict[str, int]:
    """|Sat(AF not phi)| per property by the textbook fixpoint (a deadlock loops on itself)."""
    names = [c.name for c in system.components]
    nets = system.nets
    out = {}
    for p in system.properties:
        z = {m for m in succ if not holds(p.expr, dict(zip(names, m)), nets)}
        while True:
            grown = z | {m for m, ns in succ.items() if m not in z and (ns or {m}) <= z}
            if grown == z:
                break
            z = grown
        out[p.name] = len(z)
    return out


def median_time(fn: Callable[[], object], repeats: int, before: Callable[[], None] | None = None,
                clock: Callable[[], float] = time.perf_counter) -> float:
    """Median duration of ``fn`` by ``clock`` (``time.thread_time``: CPU time, honest on a shared machine)."""
    times = []
    for _ in range(repeats):
        if before is not None:
            before()
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return statistics.median(times)


def table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A Markdown table."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    line = lambda r: "| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |"  # noqa: E731
    return "\n".join([line(cells[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [line(r) for r in cells[1:]])


def verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"
