"""(c) Peak memory per stored marking during exploration + mu1.

Each system runs in a fresh process: :mod:`tracemalloc` (which sees numpy's
buffers) records the peak of :func:`skinet.verify.predict.forecast` (complete
exploration plus mu1 for both properties), divided by the stored markings;
the process's peak resident size is shown too.  Target: <= 64 bytes per
stored marking.

    python benchmarks/bench_memory.py [--sizes 2x2,3x2,...]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
import tracemalloc

from common import copies_system, pin_one_core, table, verdict

from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.verify.explore import explore
from skinet.verify.predict import forecast

TARGET = 64.0
# The paper's literal AF: fair AF also holds the explored graph's edge list (about 32 B per edge).
LITERAL = PredictionOptions(PropertyOptions(af="literal"))
SIZES = "2x2,2x3,3x2"


def measure(n_spot: int, n_arm: int, seeds: bool) -> dict[str, float]:
    system = copies_system(n_spot, n_arm)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    tracemalloc.start()
    t0 = time.perf_counter()
    fc = forecast(system, event_seeds=seeds, options=LITERAL, memory_limit=None)
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    tracemalloc.start()
    explore(system, event_seeds=seeds, memory_limit=None)
    explore_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    report = fc.report()
    assert report["complete"]
    return {
        "markings": fc.space.markings, "box": fc.space.box, "seconds": seconds, "peak": peak,
        "explore_peak": explore_peak, "rss_growth": rss - before,
        "mu1": sum(c["dangerous"] for c in report["properties"].values()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default=SIZES, help="spot copies x manipulator copies, comma-separated")
    parser.add_argument("--one", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(int(args.one[0]), int(args.one[1]), args.one[2] == "seeds")))
        return
    pinned = pin_one_core()
    rows = []
    for size in args.sizes.split(","):
        n_spot, n_arm = map(int, size.split("x"))
        for seeds in (False, True):
            label = [f"{n_spot} spot + {n_arm} arm", "yes" if seeds else "no"]
            run = subprocess.run([sys.executable, __file__, "--one", str(n_spot), str(n_arm), "seeds" if seeds else "plain"],
                                 capture_output=True, text=True)
            if run.returncode:
                rows.append(label + [run.stderr.strip().splitlines()[-1][:70]] + ["-"] * 7)
                continue
            r = json.loads(run.stdout)
            per = r["peak"] / r["markings"]
            rows.append(label + [
                f"{r['markings']:,}", f"{r['box'] / r['markings']:.2f}", f"{r['seconds']:.2f}", f"{r['peak'] / 2**20:,.0f}",
                f"{r['explore_peak'] / r['markings']:.1f}", f"{per:.1f}", f"{r['rss_growth'] / 2**20:,.0f}", verdict(per <= TARGET),
            ])
            print(" | ".join(rows[-1]), flush=True)
    print(f"\n(c) peak memory of exploration + mu1 (both properties), tracemalloc; {pinned}; target <= {TARGET:g} B per stored marking\n")
    print(table(
        ["system", "event seeds", "stored markings", "box / stored", "forecast s", "peak MiB",
         "explore only B/marking", "explore + mu1 B/marking", "RSS growth MiB", "target"],
        rows,
    ))


if __name__ == "__main__":
    main()
