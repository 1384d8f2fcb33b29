"""Big systems (issue 10): (a) 3+3 complete, (b) 4+4 successors, (c) states/s against Spin.

(a) 3 copies of corpus spot.rl and 3 of manipulator.rl without event seeds
    (122 023 936 stable markings): complete exploration plus mu1 (both
    properties), literal AF and fair AF (the default: with CUDD,
    ``skinet.verify.symbolic``), fresh process, wall and CPU seconds, peak
    resident size.  Targets: 10 s, 1 GiB.  Baseline: fair AF by explicit SCCs
    (``symbolic.SYMBOLIC_FROM`` out of reach).  Peer: Spin on the same union
    (``skinet net --format promela``), deadline 120 s.
(b) 4 + 4 with event seeds (about 7.7e12 markings): Algorithm 1 at the
    initial marking with the default 1 s budget, fresh process: every
    successor decided or honestly unknown; wall seconds and peak resident
    size (target 1.2 GiB).  Baseline: the same without the compositional
    verdicts (docs/semantics.md §6.4), i.e. the truncated exploration alone.
(c) Stable markings per second on 2 + 2 without seeds (246 016 markings):
    ``explore()`` against Spin's ``pan`` (exhaustive, compiled -O2 outside
    the timing; compile time shown).

Each measurement runs in a fresh process.  The machine's load is printed:
figures taken on shared cores are slower than on an idle one.

    python benchmarks/bench_big.py [--only a,b,c] [--spin-deadline 120]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, copies_system, table, verdict

GiB = 1 << 30


def one(kind: str) -> dict:
    """Run in a fresh process: one measurement, as JSON."""
    from skinet.system.prediction import PredictionOptions, PropertyOptions
    from skinet.verify.algorithm1 import analyse
    from skinet.verify.explore import explore, peak_resident_bytes
    from skinet.verify.predict import forecast

    from skinet.verify import symbolic

    literal = PredictionOptions(PropertyOptions(af="literal"))
    fair = PredictionOptions(PropertyOptions(af="fair"))
    if kind in ("a", "a-fair", "a-fair-base"):
        system = copies_system(3, 3)
        if kind == "a-fair-base":
            symbolic.SYMBOLIC_FROM = 1 << 62
        import scipy.sparse.csgraph  # noqa: F401  (forecast's one-time import, outside the clock as there)

        w, c = time.perf_counter(), time.process_time()
        fc = forecast(system, event_seeds=False, options=literal if kind == "a" else fair, memory_limit=GiB)
        out = {"report": fc.report()}
    elif kind in ("b", "b-base"):
        system = copies_system(4, 4)
        t0 = time.perf_counter()
        import scipy.sparse.csgraph  # noqa: F401  (one-time start-up, shown apart)

        imported = time.perf_counter() - t0
        w, c = time.perf_counter(), time.process_time()
        fc = forecast(system, budget=1.0, compositional=kind == "b")
        analysis = analyse(system, system.initial_marking(), fc)
        kinds: dict[str, int] = {}
        for u in analysis.unsafe:
            kinds[u.constraint] = kinds.get(u.constraint, 0) + 1
        out = {"report": fc.report(), "kinds": kinds, "import": imported}
    else:
        system = copies_system(2, 2)
        w, c = time.perf_counter(), time.process_time()
        space = explore(system, event_seeds=False, memory_limit=None)
        out = {"markings": space.markings}
    out.update(wall=time.perf_counter() - w, cpu=time.process_time() - c,
               peak=peak_resident_bytes())
    return out


def fresh(kind: str) -> dict:
    run = subprocess.run([sys.executable, __file__, "--one", kind], capture_output=True, text=True, timeout=1800)
    if run.returncode:
        raise SystemExit(run.stderr)
    return json.loads(run.stdout)


def spin(n_spot: int, n_arm: int, deadline: float) -> dict:
    """Spin on the eventless union: compile seconds, run seconds, states stored (or partial)."""
    from skinet.net.export.promela import to_promela
    from skinet.net.union import union

    system = copies_system(n_spot, n_arm)
    work = Path(tempfile.mkdtemp(prefix="skinet-spin-"))
    (work / "m.pml").write_text(to_promela(union([c.eventless for c in system.components], system.name)))
    t0 = time.perf_counter()
    subprocess.run(["spin", "-a", "m.pml"], cwd=work, check=True, capture_output=True)
    subprocess.run(["gcc", "-O2", "-DNOCLAIM", "-DSAFETY", "-DMEMLIM=16384", "-o", "pan", "pan.c"], cwd=work,
                   check=True, capture_output=True)
    compiled = time.perf_counter() - t0
    t0 = time.perf_counter()
    try:
        out = subprocess.run(["./pan", "-E", "-m10000000"], cwd=work, capture_output=True, text=True,
                             timeout=deadline).stdout
        finished = True
    except subprocess.TimeoutExpired as exc:
        out = (exc.stdout or b"").decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        finished = False
    seconds = time.perf_counter() - t0
    shutil.rmtree(work, ignore_errors=True)
    found = re.search(r"(\d+) states, stored", out)
    return {"compile": compiled, "seconds": seconds, "finished": finished, "states": int(found.group(1)) if found else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", default="a,b,c")
    parser.add_argument("--spin-deadline", type=float, default=120.0)
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one(args.one)))
        return
    have_spin = shutil.which("spin") is not None and shutil.which("gcc") is not None
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; spin {'found' if have_spin else 'missing'}")
    only = args.only.split(",")
    if "a" in only:
        rows = []
        for kind, label in (("a", "ours: explore + literal mu1"), ("a-fair", "ours: explore + fair mu1 (CUDD)"),
                            ("a-fair-base", "baseline: explore + fair mu1 by explicit SCCs")):
            r = fresh(kind)
            rep = r["report"]
            dangerous = ", ".join(f"{p} {c['dangerous']:,}" for p, c in rep["properties"].items())
            rows.append([label, f"{rep['markings']:,}", "yes" if rep["complete"] else rep["truncated_by"], dangerous,
                         f"{r['wall']:.1f}", f"{r['cpu']:.1f}", f"{r['peak'] / 2**20:,.0f}",
                         verdict(rep["complete"] and r["wall"] <= 10 and r["peak"] <= GiB)
                         if kind != "a-fair-base" else "-"])
        if have_spin:
            s = spin(3, 3, args.spin_deadline)
            rows.append([f"Spin (compile {s['compile']:.0f} s, not timed)", f"{s['states'] or '-'}",
                         "yes" if s["finished"] else f"no ({args.spin_deadline:g} s deadline)", "-",
                         f"{s['seconds']:.1f}", "-", "-", "-"])
        print("\n(a) 3 spot + 3 arm, no seeds: complete + mu1; targets 10 s, 1 GiB\n")
        print(table(["run", "markings", "complete", "dangerous", "wall s", "cpu s", "peak MiB", "target"], rows))
    if "b" in only:
        rows = []
        for kind, label in (("b", "ours: exploration + compositional verdicts"), ("b-base", "baseline: exploration alone")):
            r = fresh(kind)
            kinds = ", ".join(f"{k} {v}" for k, v in sorted(r["kinds"].items())) or "none"
            rows.append([label, kinds, f"{r['wall']:.2f}", f"{r['import']:.2f}", f"{r['peak'] / 2**20:,.0f}",
                         verdict(r["wall"] <= 1.5 and r["peak"] <= 1.2 * GiB) if kind == "b" else "-"])
        print("\n(b) 4 spot + 4 arm with seeds, initial marking, budget 1 s: forecast + Algorithm 1, "
              "unsafe entries by kind (none: every successor decided safe); targets 1.5 s, 1.2 GiB\n")
        print(table(["run", "unsafe entries", "wall s", "scipy import s (before)", "peak MiB", "target"], rows))
    if "c" in only:
        r = fresh("c")
        rows = [["ours: explore()", f"{r['markings']:,}", f"{r['wall']:.2f}", f"{r['markings'] / r['wall']:,.0f}"]]
        if have_spin:
            s = spin(2, 2, args.spin_deadline)
            rate = (s["states"] or 0) / s["seconds"]
            rows.append([f"Spin pan (compile {s['compile']:.0f} s, not timed)", f"{s['states'] or '-'}",
                         f"{s['seconds']:.2f}", f"{rate:,.0f}"])
            print(f"\nratio ours / Spin: {r['markings'] / r['wall'] / rate:.1f}x" if rate else "")
        print("\n(c) 2 spot + 2 arm, no seeds: stable markings per second\n")
        print(table(["run", "markings", "seconds", "markings/s"], rows))


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    main()
