"""(a) The paper's system: complete exploration plus mu1 for both properties.

Compared with the seed paper's 14 ms for Tina (its figure, not measured here)
and with the pure-Python baseline of :mod:`common`, measured in the same run;
target: 2 ms.  Skillset files are parsed once, outside the timed region.

    python benchmarks/bench_paper.py [--repeats N] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import statistics
import subprocess
import sys
import time

from common import baseline_explore, baseline_mu1, forget, median_time, paper_system, pin_one_core, table, verdict

from skinet.verify.predict import forecast

TINA_MS = 14.0
TARGET_MS = 2.0


def cold_once() -> None:
    """Print the time of this fresh process's first forecast (cache empty, numpy never called)."""
    system = paper_system()
    t0 = time.perf_counter()
    forecast(system)
    print(json.dumps(time.perf_counter() - t0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--cold-processes", type=int, default=7)
    parser.add_argument("--profile", action="store_true", help="profile the uncached forecast")
    parser.add_argument("--cold-once", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.cold_once:
        return cold_once()
    pinned = pin_one_core()
    system = paper_system()
    fc = forecast(system)
    report = fc.report()
    assert report["complete"]
    mu1 = {p: c["dangerous"] for p, c in report["properties"].items()}

    colds = [
        json.loads(subprocess.run([sys.executable, __file__, "--cold-once"], capture_output=True, text=True, check=True).stdout)
        for _ in range(args.cold_processes)
    ]
    cold = statistics.median(colds)
    uncached = median_time(lambda: forecast(system), args.repeats, before=lambda: forget(system))
    warm = median_time(lambda: forecast(system), args.repeats)

    base = baseline_explore(system, event_seeds=True)
    base_mu1 = baseline_mu1(system, base.succ)
    assert (base.markings, base.edges, base_mu1) == (report["markings"], report["edges"], mu1), "baseline disagrees"
    baseline = median_time(lambda: baseline_mu1(system, baseline_explore(system).succ), max(5, args.repeats // 20))

    def row(what: str, seconds: float, target: bool = True) -> list[object]:
        ms = seconds * 1e3
        return [what, f"{ms:.3f}", f"{TINA_MS / ms:.1f}x", verdict(ms <= TARGET_MS) if target else "-"]

    print(f"(a) paper system {system.name}: {report['markings']} stable markings, {report['edges']} edges, "
          f"depth {report['depth']}, mu1 {mu1}; {pinned}; medians over {args.repeats} runs\n")
    print(table(
        ["figure", "ms", "speed-up vs Tina 14 ms", f"target <= {TARGET_MS:g} ms"],
        [
            row(f"ours, cold (first call in a fresh process, median of {len(colds)})", cold),
            row("ours, uncached (component graphs rebuilt every call)", uncached),
            row("ours, warm (component graphs memoised)", warm),
            row("baseline: pure-Python BFS + mu1, same run", baseline, target=False),
            ["Tina (paper figure, not measured here)", f"{TINA_MS:.3f}", "1.0x", "-"],
        ],
    ))
    print(f"\nours vs baseline: {baseline / warm:.0f}x warm, {baseline / uncached:.0f}x uncached, {baseline / cold:.0f}x cold")

    if args.profile:
        prof = cProfile.Profile()
        for _ in range(args.repeats):
            forget(system)
            prof.enable()
            forecast(system)
            prof.disable()
        stats = pstats.Stats(prof)
        total = stats.total_tt  # type: ignore[attr-defined]
        shares = {}
        for (file, _, func), (_, _, _, cum, _) in stats.stats.items():  # type: ignore[attr-defined]
            if func in ("component_graphs", "explore_graphs", "__init__", "check") and "skinet/verify" in file:
                shares[f"{file.rsplit('/', 1)[-1]}:{func}"] = cum
        print(f"\nprofile of {args.repeats} uncached forecasts (cumulative share of {total * 1e3 / args.repeats:.3f} ms per call, "
              "profiler overhead included):")
        for name, cum in sorted(shares.items(), key=lambda kv: -kv[1]):
            print(f"  {name:40s} {100 * cum / total:5.1f} %")
        stats.sort_stats("tottime").print_stats(12)


if __name__ == "__main__":
    main()
