"""Decision diagrams against ours on big systems (issue 10, item 2's evaluation).

The stable-marking graph of the eventless union is the asynchronous product
of the components' stable graphs (``skinet.verify.component``).  Here it is
encoded as a BDD: each component's local states (its
:class:`~skinet.verify.component.ComponentGraph` indices) in binary
variables ``x``, primed copies ``y`` for successors (``x``/``y`` bits
interleaved, components in the system's order), and one relation
``T_i(x_i, y_i)`` per component (its steps, self-loops included).  The product
step is "one component moves, the others stay", computed as a per-component
partitioned image ``Img_i(S) = (exists x_i. S and T_i)[y_i := x_i]``, so the
frame conditions are never built.  On top of that, with ``dd.autoref`` (pure
Python), ``dd.cudd`` (CUDD, from the PyPI wheel) and ``oxidd`` (its BDD
manager):

(1) the reachable set from the sources docs/semantics.md §6 names (the live marking, and
    with event seeds the markings one event leads to), by chained
    partitioned images, and its number of markings;
(2) mu1 per property: literal ``AF not phi = reach and not EG phi``, ``EG phi``
    the greatest fixpoint of ``phi and reach and EX Z`` (a global deadlock
    loops on itself, docs/semantics.md §6.2); fair AF with fair-EG by Emerson-Lei, one
    fairness constraint per skill (its idle place), counted;
(3) 4 + 4 with seeds: the verdict of ``AF not phi`` at every one-step
    successor (steps of the full nets, as Algorithm 1 asks) of the initial
    marking and of ``--walks`` live markings after 40 seeded random steps,
    ``EG phi`` computed over the whole product of the component graphs (no
    reachability needed: a graph holds everything reachable from its states);
(4) 4 + 4 with seeds: the reachable set, which our explicit search cannot
    store (about 7.7e12 markings in the box).

Ours, in the same run, with the same AF: ``forecast`` (complete exploration +
mu1, 1 GiB memory limit) for (1)-(2); ``forecast(budget=1.0)`` (truncated
exploration plus the compositional verdicts, docs/semantics.md §6.4) and Algorithm 1 per
live marking for (3).  Each case runs
in a fresh process with a deadline (``--deadline``, default 120 s); one that
does not finish prints "no (deadline)".  Times are wall seconds inside the
process after the system is parsed (component graphs, encoding and fixpoints
included); peak is the process's peak resident size (Python, numpy and the
parsed system included, about 60-70 MiB before any work).  Counts must equal
ours, or the row says so.

Needs the optional ``bench`` extra::

    pip install -e '.[bench]'          # oxidd (dd, with dd.cudd in its wheel, is a dependency)
    python benchmarks/bench_dd.py [--only 1,2,3,4] [--tools ours,dd.autoref,dd.cudd,oxidd]
                                  [--af literal,fair] [--walks 4] [--deadline 120]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from common import ROOT, copies_system, pin_one_core, table

TOOLS = ("ours", "dd.autoref", "dd.cudd", "oxidd")
GiB = 1 << 30
OXIDD_NODES = 1 << 25  # inner-node capacity of the oxidd manager (it does not grow)
OXIDD_CACHE = 1 << 22  # apply-cache entries


# --------------------------------------------------------------------------- backends


class Backend:
    """The few BDD operations the encoding needs, over named variables."""

    def declare(self, names: Sequence[str]) -> None: ...
    def var(self, name: str) -> Any: ...
    def true(self) -> Any: ...
    def false(self) -> Any: ...
    def exists(self, names: Sequence[str], f: Any) -> Any: ...
    def and_exists(self, f: Any, g: Any, names: Sequence[str]) -> Any: ...
    def rename(self, f: Any, pairs: Mapping[str, str]) -> Any: ...
    def count(self, f: Any, names: Sequence[str]) -> int: ...
    def nodes(self) -> int: ...


class DD(Backend):
    """``dd.autoref`` (pure Python) or ``dd.cudd`` (CUDD): the same API."""

    def __init__(self, module: str):
        if module == "dd.cudd":
            import dd.cudd as mod

            self._and_exists = mod.and_exists
        else:
            import dd.autoref as mod

            self._and_exists = None
        self.bdd = mod.BDD()

    def declare(self, names: Sequence[str]) -> None:
        self.bdd.declare(*names)

    def var(self, name: str) -> Any:
        return self.bdd.var(name)

    def true(self) -> Any:
        return self.bdd.true

    def false(self) -> Any:
        return self.bdd.false

    def exists(self, names: Sequence[str], f: Any) -> Any:
        return self.bdd.exist(names, f)

    def and_exists(self, f: Any, g: Any, names: Sequence[str]) -> Any:
        if self._and_exists is not None:
            return self._and_exists(f, g, set(names))
        return self.bdd.exist(names, f & g)

    def rename(self, f: Any, pairs: Mapping[str, str]) -> Any:
        return self.bdd.let(dict(pairs), f)

    def count(self, f: Any, names: Sequence[str]) -> int:
        return int(self.bdd.count(f, nvars=len(names)))

    def nodes(self) -> int:
        return len(self.bdd)


class OxiDD(Backend):
    """``oxidd.bdd.BDDManager`` (no complement edges), one thread."""

    def __init__(self) -> None:
        from oxidd.bdd import BDDFunction, BDDManager
        from oxidd.util import BooleanOperator

        self.manager = BDDManager(OXIDD_NODES, OXIDD_CACHE, 1)
        self._subst = BDDFunction.make_substitution
        self._and = BooleanOperator.AND
        self.index: dict[str, int] = {}
        self._cubes: dict[tuple[str, ...], Any] = {}
        self._substitutions: dict[tuple[tuple[str, str], ...], Any] = {}

    def declare(self, names: Sequence[str]) -> None:
        for name, v in zip(names, self.manager.add_named_vars(names)):
            self.index[name] = v

    def var(self, name: str) -> Any:
        return self.manager.var(self.index[name])

    def true(self) -> Any:
        return self.manager.true()

    def false(self) -> Any:
        return self.manager.false()

    def _cube(self, names: Sequence[str]) -> Any:
        key = tuple(names)
        if key not in self._cubes:
            c = self.manager.true()
            for n in names:
                c = c & self.var(n)
            self._cubes[key] = c
        return self._cubes[key]

    def exists(self, names: Sequence[str], f: Any) -> Any:
        return f.exists(self._cube(names))

    def and_exists(self, f: Any, g: Any, names: Sequence[str]) -> Any:
        return f.apply_exists(self._and, g, self._cube(names))

    def rename(self, f: Any, pairs: Mapping[str, str]) -> Any:
        key = tuple(pairs.items())
        if key not in self._substitutions:  # reused: its apply-cache entries stay valid
            self._substitutions[key] = self._subst([(self.index[a], self.var(b)) for a, b in key])
        return f.substitute(self._substitutions[key])

    def count(self, f: Any, names: Sequence[str]) -> int:
        total = self.manager.num_vars()
        return f.sat_count(total) >> (total - len(names))

    def nodes(self) -> int:
        return self.manager.num_inner_nodes()


def backend(tool: str) -> Backend:
    return OxiDD() if tool == "oxidd" else DD(tool)


# --------------------------------------------------------------------------- encoding


class Encoding:
    """The product of component graphs as BDDs: local state codes, relations, phi."""

    def __init__(self, bdd: Backend, graphs: Sequence[Any]):
        self.bdd = bdd
        from skinet.verify.symbolic import variables  # the predictor's own encoding

        self.graphs = list(graphs)
        self.x, self.y, order = variables(self.graphs)
        bdd.declare(order)
        self.xs = [v for vs in self.x for v in vs]
        self.to_y = [dict(zip(self.x[i], self.y[i])) for i in range(len(self.graphs))]
        self.to_x = [dict(zip(self.y[i], self.x[i])) for i in range(len(self.graphs))]
        self.relation = [self._relation(i) for i in range(len(self.graphs))]
        dead = bdd.true()
        for i, g in enumerate(self.graphs):
            dead &= self.states(i, [s for s in range(g.size) if not g.succ[s] and not g.loop[s]])
        self.deadlock = dead  # a global deadlock: every component stuck

    def code(self, names: Sequence[str], value: int) -> Any:
        f = self.bdd.true()
        for b, n in enumerate(names):
            f &= self.bdd.var(n) if value >> b & 1 else ~self.bdd.var(n)
        return f

    def states(self, i: int, indices: Iterable[int], primed: bool = False) -> Any:
        f = self.bdd.false()
        for s in indices:
            f |= self.code(self.y[i] if primed else self.x[i], s)
        return f

    def _relation(self, i: int) -> Any:
        g = self.graphs[i]
        rel = self.bdd.false()
        for a in range(g.size):
            targets = list(g.succ[a]) + ([a] if g.loop[a] else [])
            if targets:
                rel |= self.code(self.x[i], a) & self.states(i, targets, primed=True)
        return rel

    def marking(self, local: Mapping[str, int]) -> Any:
        """The cube of one combined marking (local markings by component name)."""
        f = self.bdd.true()
        for i, g in enumerate(self.graphs):
            f &= self.code(self.x[i], g.index[local[g.name]])
        return f

    def valid(self) -> Any:
        f = self.bdd.true()
        for i, g in enumerate(self.graphs):
            f &= self.states(i, range(g.size))
        return f

    def sources(self) -> Any:
        """docs/semantics.md §6's sources: every combination of roots, plus one component moved to a seed."""
        roots = [self.states(i, g.roots) for i, g in enumerate(self.graphs)]
        f = self.bdd.true()
        for r in roots:
            f &= r
        for i, g in enumerate(self.graphs):
            if g.seeds:
                one = self.states(i, g.seeds)
                for j, r in enumerate(roots):
                    if j != i:
                        one &= r
                f |= one
        return f

    def image(self, i: int, s: Any) -> Any:
        return self.bdd.rename(self.bdd.and_exists(s, self.relation[i], self.x[i]), self.to_x[i])

    def preimage(self, i: int, z: Any) -> Any:
        return self.bdd.and_exists(self.bdd.rename(z, self.to_y[i]), self.relation[i], self.y[i])

    def reach(self) -> tuple[Any, int]:
        """Chained partitioned images to the fixpoint; returns the set and the sweeps made."""
        reach = self.sources()
        sweeps = 0
        changed = True
        while changed:
            changed = False
            sweeps += 1
            for i in range(len(self.graphs)):
                while True:
                    new = self.image(i, reach) & ~reach
                    if new == self.bdd.false():
                        break
                    reach |= new
                    changed = True
        return reach, sweeps

    def eg(self, p: Any) -> tuple[Any, int]:
        """Greatest fixpoint of ``p and EX Z`` (deadlocks loop on themselves)."""
        z = p
        rounds = 0
        while True:
            rounds += 1
            nz = p & self.ex(z)
            if nz == z:
                return z, rounds
            z = nz

    def ex(self, z: Any) -> Any:
        pre = z & self.deadlock
        for i in range(len(self.graphs)):
            pre |= self.preimage(i, z)
        return pre

    def eu(self, f: Any, g: Any) -> Any:
        """Least fixpoint ``E[f U g]``."""
        y = g
        while True:
            ny = y | (f & self.ex(y))
            if ny == y:
                return y
            y = ny

    def fair_eg(self, f: Any, fairness: Sequence[Any]) -> tuple[Any, int]:
        """Emerson-Lei: greatest fixpoint of ``f and AND_k EX E[f U (Z and F_k)]`` (docs/semantics.md §6.2)."""
        z = f
        rounds = 0
        while True:
            rounds += 1
            nz = f
            for fk in fairness:
                nz &= self.ex(self.eu(f, z & fk))
            if nz == z:
                return z, rounds
            z = nz

    def idle(self, system: Any) -> list[Any]:
        """One fairness constraint per skill: its idle place is marked (docs/semantics.md §6.2)."""
        from skinet.verify.fair import idle_atoms

        return [self.formula(a) for a in idle_atoms(self.graphs, system)]

    def formula(self, expr: Any) -> Any:
        """A state formula (docs/semantics.md §4) as a BDD over the local state codes."""
        from skinet.props.evaluate import evaluate

        by_name = {g.name: i for i, g in enumerate(self.graphs)}

        def atom(a: Any) -> Any:
            i = by_name[a.skillset]
            g = self.graphs[i]
            bit = g.net.place_index(a.place)
            return self.states(i, [s for s, m in enumerate(g.states) if m >> bit & 1])

        return evaluate(expr, atom, lambda v: self.bdd.true() if v else self.bdd.false())


# --------------------------------------------------------------------------- one case, fresh process


SYSTEMS = {"1": (2, 2, False), "2": (3, 3, False), "3": (4, 4, True), "4": (4, 4, True)}


def live_markings(system: Any, walks: int) -> list[dict[str, int]]:
    """The initial marking, then ``walks`` live markings after 40 seeded random steps of the full nets."""
    import random

    from skinet.net.semantics import steps

    out = [system.initial_marking()]
    for seed in range(1, walks + 1):
        rng = random.Random(seed)
        marking = system.initial_marking()
        for _ in range(40):
            comp = rng.choice(system.components)
            options = steps(comp.net, marking[comp.name])
            if options:
                _t, results = rng.choice(options)
                marking[comp.name] = rng.choice(sorted(results))
        out.append(marking)
    return out


def successors(system: Any, marking: Mapping[str, int]) -> list[dict[str, int]]:
    """Every distinct one-step successor of ``marking`` through the full nets (Algorithm 1's)."""
    from skinet.net.semantics import steps

    out: dict[tuple[int, ...], dict[str, int]] = {}
    for comp in system.components:
        for _, results in steps(comp.net, marking[comp.name]):
            for m in results:
                after = dict(marking)
                after[comp.name] = m
                out.setdefault(tuple(after[c.name] for c in system.components), after)
    return list(out.values())


def pair_verdicts(system: Any, marking: Mapping[str, int], decide: Any) -> list[str]:
    """explicit / dangerous / safe / unknown per (successor, property), in a fixed order."""
    from skinet.props.evaluate import holds

    out = []
    for after in successors(system, marking):
        for p in system.properties:
            out.append("explicit" if not holds(p.expr, after, system.nets) else decide(p, after))
    return out


def run_ours(case: str, af: str, walks: int) -> dict:
    from skinet.system.prediction import PredictionOptions, PropertyOptions
    from skinet.verify.algorithm1 import analyse
    from skinet.verify.predict import forecast

    n, m, seeds = SYSTEMS[case]
    system = copies_system(n, m)
    options = PredictionOptions(PropertyOptions(af=af))
    import scipy.sparse.csgraph  # noqa: F401  (forecast's one-time import, outside the clock as there)

    t0 = time.perf_counter()
    if case in ("1", "2"):
        fc = forecast(system, event_seeds=False, options=options, memory_limit=GiB)
        rep = fc.report()
        return {"wall": time.perf_counter() - t0, "markings": rep["markings"], "complete": rep["complete"],
                "truncated_by": rep["truncated_by"],
                "dangerous": {k: v["dangerous"] for k, v in rep["properties"].items()}}
    if case == "3":
        status = {"dangerous": "dangerous", "safe": "safe"}
        verdicts: list[str] = []
        unsafe = explored = 0
        walls = []
        for live in live_markings(system, walks):
            t1 = time.perf_counter()
            fc = forecast(system, live, budget=1.0, options=options)
            unsafe += len(analyse(system, live, fc, options=options).unsafe)
            verdicts += pair_verdicts(system, live,
                                      lambda p, after: status.get(fc.verdict(p.name, after).status, "unknown"))
            explored += fc.report()["markings"]
            walls.append(time.perf_counter() - t1)
        return {"wall": time.perf_counter() - t0, "verdicts": verdicts, "unsafe": unsafe, "markings": explored,
                "worst": max(walls)}
    return {"wall": time.perf_counter() - t0, "skipped": True}


def run_bdd(case: str, tool: str, af: str, walks: int) -> dict:
    n, m, seeds = SYSTEMS[case]
    system = copies_system(n, m)
    if case == "3":
        t0 = time.perf_counter()
        verdicts: list[str] = []
        walls = []
        for live in live_markings(system, walks):
            t1 = time.perf_counter()
            bdd = backend(tool)  # a new manager per live marking: its component graphs differ
            enc = Encoding(bdd, component_graphs(system, live, event_seeds=True, extra=successors(system, live)))
            fairness = enc.idle(system) if af == "fair" else []
            valid = enc.valid()
            sets = {p.name: (enc.fair_eg(valid & enc.formula(p.expr), fairness) if af == "fair"
                             else enc.eg(valid & enc.formula(p.expr)))[0] for p in system.properties}
            verdicts += pair_verdicts(system, live, lambda p, after: "safe" if (enc.marking(after) & sets[p.name])
                                      != bdd.false() else "dangerous")
            walls.append(time.perf_counter() - t1)
        return {"wall": time.perf_counter() - t0, "verdicts": verdicts, "worst": max(walls), "nodes": bdd.nodes()}
    bdd = backend(tool)
    t0 = time.perf_counter()
    graphs = component_graphs(system, system.initial_marking(), event_seeds=seeds)
    enc = Encoding(bdd, graphs)
    out: dict[str, Any] = {"encode": time.perf_counter() - t0}
    fairness = enc.idle(system) if af == "fair" else []

    def eg(f: Any) -> tuple[Any, int]:
        return enc.fair_eg(f, fairness) if af == "fair" else enc.eg(f)

    t1 = time.perf_counter()
    reach, sweeps = enc.reach()
    out.update(reach=time.perf_counter() - t1, markings=bdd.count(reach, enc.xs), sweeps=sweeps)
    if case in ("1", "2"):
        t1 = time.perf_counter()
        out["dangerous"], out["rounds"] = {}, {}
        for p in system.properties:
            z, rounds = eg(reach & enc.formula(p.expr))
            out["dangerous"][p.name] = bdd.count(reach & ~z, enc.xs)
            out["rounds"][p.name] = rounds
        out["mu1"] = time.perf_counter() - t1
    out["wall"] = time.perf_counter() - t0
    out["nodes"] = bdd.nodes()
    return out


def component_graphs(system: Any, live: Mapping[str, int], event_seeds: bool,
                     extra: Sequence[Mapping[str, int]] = ()) -> list[Any]:
    """``skinet.verify.explore.component_graphs``, widened where a successor's local marking is not in it."""
    from skinet.verify.component import explore_component
    from skinet.verify.explore import component_graphs as graphs_of

    graphs = graphs_of(system, live, event_seeds=event_seeds)
    out = []
    for comp, g in zip(system.components, graphs):
        missing = {after[comp.name] for after in extra} - set(g.index)
        if missing:  # a transient successor is stabilized by explore_component; its stable results join
            seeds = [g.states[s] for s in g.seeds]
            g = explore_component(comp.name, comp.eventless, [live[comp.name], *sorted(missing)], seeds)
        out.append(g)
    return out


def one(case: str, tool: str, af: str, walks: int) -> dict:
    from skinet.verify.explore import peak_resident_bytes

    out = run_ours(case, af, walks) if tool == "ours" else run_bdd(case, tool, af, walks)
    out["peak"] = peak_resident_bytes()
    return out


def fresh(case: str, tool: str, af: str, deadline: float, walks: int = 0) -> dict:
    """``one(case, tool, af, walks)`` in a new process; ``{"deadline": True}`` when it does not finish in time."""
    try:
        run = subprocess.run([sys.executable, __file__, "--one", f"{case}:{tool}:{af}:{walks}"], capture_output=True,
                             text=True, timeout=deadline)
    except subprocess.TimeoutExpired:  # subprocess.run has killed it
        return {"deadline": True}
    if run.returncode:
        last = (run.stderr.strip().splitlines() or ["exit status %d" % run.returncode])[-1]
        return {"error": last[:80]}
    return json.loads(run.stdout)


# --------------------------------------------------------------------------- the tables


def missing_tools(tools: Sequence[str]) -> list[str]:
    need = {"dd.autoref": "dd", "dd.cudd": "dd.cudd", "oxidd": "oxidd.bdd"}
    out = []
    for t in tools:
        if t == "ours":
            continue
        try:
            if importlib.util.find_spec(need[t]) is None:
                out.append(t)
        except (ModuleNotFoundError, ValueError):  # parent package missing, or blocked
            out.append(t)
    return out


def mib(r: dict) -> str:
    return f"{r['peak'] / 2**20:,.0f}"


def failed(r: dict) -> str | None:
    if r.get("deadline"):
        return "no (deadline)"
    if "error" in r:
        return f"no ({r['error']})"
    return None


def counts_rows(case: str, tools: Sequence[str], af: str, deadline: float) -> list[list[str]]:
    results = {t: fresh(case, t, af, deadline) for t in tools}
    ref = results.get("ours", {})
    rows = []
    for t, r in results.items():
        if (why := failed(r)) is not None:
            rows.append([t, af, why, "-", "-", "-", "-", "-", "-"])
            continue
        dangerous = ", ".join(f"{k} {v:,}" for k, v in sorted(r["dangerous"].items()))
        if t == "ours" or not ref or failed(ref) or not ref["complete"]:
            same = "-"
        else:
            same = "yes" if r["markings"] == ref["markings"] and r["dangerous"] == ref["dangerous"] else "NO"
        phases = "-" if t == "ours" else f"{r['encode']:.2f} / {r['reach']:.2f} / {r['mu1']:.2f}"
        complete = "yes" if r.get("complete", True) else f"no ({r['truncated_by']})"
        rows.append([t, af, complete, f"{r['markings']:,}", dangerous, same, phases, f"{r['wall']:.2f}", mib(r)])
    return rows


def verdict_rows(tools: Sequence[str], af: str, deadline: float, walks: int) -> list[list[str]]:
    results = {t: fresh("3", t, af, deadline, walks) for t in tools}
    ref = results.get("ours", {})
    rows = []
    for t, r in results.items():
        if (why := failed(r)) is not None:
            rows.append([t, af, why, "-", "-", "-", "-"])
            continue
        v = r["verdicts"]
        tally = ", ".join(f"{k} {v.count(k)}" for k in ("explicit", "dangerous", "safe", "unknown") if v.count(k))
        if t == "ours":
            against = f"{r['markings']:,} markings explored in all, {r['unsafe']} unsafe entries"
        elif ref and not failed(ref):
            rv = ref["verdicts"]
            agree = sum(a == b for a, b in zip(v, rv) if b != "unknown")
            decided = sum(b != "unknown" for b in rv)
            against = f"same verdict on {agree} of ours' {decided} decided"
        else:
            against = "-"
        rows.append([t, af, tally, against, f"{r['worst']:.2f}", f"{r['wall']:.2f}", mib(r)])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", default="1,2,3,4",
                        help="cases (1: 2+2, 2: 3+3, 3: 4+4 successor verdicts, 4: 4+4 reachable set)")
    parser.add_argument("--tools", default=",".join(TOOLS), help="comma-separated, from " + ", ".join(TOOLS))
    parser.add_argument("--af", default="literal,fair", help="AF semantics for cases 1-3: literal, fair or both")
    parser.add_argument("--walks", type=int, default=4,
                        help="case 3: live markings after seeded random walks, besides the initial marking")
    parser.add_argument("--deadline", type=float, default=120.0, help="seconds per case and tool (fresh process)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        case, tool, af, walks = args.one.split(":")
        print(json.dumps(one(case, tool, af, int(walks))))
        return
    tools = [t for t in args.tools.split(",") if t]
    if bad := [t for t in tools if t not in TOOLS]:
        raise SystemExit(f"bench_dd: unknown tool {bad[0]!r} (choose from {', '.join(TOOLS)})")
    if lacking := missing_tools(tools):
        raise SystemExit(f"bench_dd: {', '.join(lacking)} not installed; install the bench extra: "
                         "pip install -e '.[bench]' (oxidd from PyPI), or pass --tools without them")
    only = args.only.split(",")
    if bad := [c for c in only if c not in SYSTEMS]:
        raise SystemExit(f"bench_dd: unknown case {bad[0]!r} (choose from 1, 2, 3, 4)")
    afs = args.af.split(",")
    if bad := [a for a in afs if a not in ("literal", "fair")]:
        raise SystemExit(f"bench_dd: unknown AF {bad[0]!r} (choose from literal, fair)")
    from importlib.metadata import PackageNotFoundError, version

    versions = []
    for mod in ("dd", "oxidd"):
        try:
            versions.append(f"{mod} {version(mod)}")
        except PackageNotFoundError:
            versions.append(f"{mod} missing")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {pin_one_core()}; "
          f"{', '.join(versions)}; deadline {args.deadline:g} s per case")
    headers = ["run", "AF", "complete", "markings", "dangerous (mu1)", "= ours", "encode / reach / mu1 s",
               "wall s", "peak MiB"]
    for case, title in (("1", "2 spot + 2 arm, no seeds (246 016 markings)"),
                        ("2", "3 spot + 3 arm, no seeds (122 023 936 markings)")):
        if case in only:
            print(f"\n({case}) {title}: reachable set + mu1 for both properties\n")
            print(table(headers, [row for af in afs for row in counts_rows(case, tools, af, args.deadline)]))
    if "3" in only:
        print(f"\n(3) 4 spot + 4 arm with seeds: AF not phi at every one-step successor x property, at the "
              f"initial marking and {args.walks} live markings after 40 random steps (ours: forecast with "
              f"budget 1 s + Algorithm 1 per live marking)\n")
        print(table(["run", "AF", "verdicts (successor x property)", "against ours", "worst marking s", "wall s",
                     "peak MiB"], [row for af in afs for row in verdict_rows(tools, af, args.deadline, args.walks)]))
    if "4" in only:
        rows = []
        for t in tools:
            if t == "ours":
                rows.append([t, "no (not attempted: the box holds 7 666 785 058 816 markings)", "-", "-", "-"])
                continue
            r = fresh("4", t, "literal", args.deadline)
            if (why := failed(r)) is not None:
                rows.append([t, why, "-", "-", "-"])
                continue
            rows.append([t, f"{r['markings']:,}", f"{r['encode']:.2f} / {r['reach']:.2f}", f"{r['wall']:.2f}", mib(r)])
        print("\n(4) 4 spot + 4 arm with seeds: reachable set\n")
        print(table(["run", "markings", "encode / reach s", "wall s", "peak MiB"], rows))


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    main()
