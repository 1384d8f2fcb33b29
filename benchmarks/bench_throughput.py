"""(b) Throughput in stable markings per second on growing systems.

Systems: n copies of corpus spot.rl and m of manipulator.rl, renamed
(spot, spot2, ...), explored from the initial marking with and without event
seeds.  Ours is :func:`skinet.verify.explore.explore` end to end, component
graphs rebuilt (not memoised); the baseline is the pure-Python BFS of
:mod:`common`, run only where it finishes within the deadline (nothing is
extrapolated).  Targets: >= 2 million markings/s and >= 10x the baseline.

    python benchmarks/bench_throughput.py [--deadline 60] [--sizes 1x1,2x2,...]
"""

from __future__ import annotations

import argparse

from common import baseline_explore, copies_system, forget, median_time, pin_one_core, table, verdict

from skinet.verify.explore import explore

TARGET_RATE = 2e6
TARGET_RATIO = 10.0
SIZES = "1x1,1x2,2x1,1x3,2x2,2x3,3x2,3x3"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--deadline", type=float, default=60.0, help="seconds the baseline may take per system")
    parser.add_argument("--sizes", default=SIZES, help="spot copies x manipulator copies, comma-separated")
    args = parser.parse_args()
    pinned = pin_one_core()
    rows = []
    for size in args.sizes.split(","):
        n_spot, n_arm = map(int, size.split("x"))
        system = copies_system(n_spot, n_arm)
        for seeds in (False, True):
            label = [f"{n_spot} spot + {n_arm} arm", "yes" if seeds else "no"]
            space = explore(system, event_seeds=seeds)
            if not space.complete:  # over the default memory limit: truncated, not a throughput figure
                rows.append(label + [f"truncated by {space.truncated_by} at {space.markings:,}", "-"] + ["-"] * 8)
                continue
            repeats = 5 if space.markings < 1e6 else 1
            seconds = median_time(lambda: explore(system, event_seeds=seeds), repeats, before=lambda: forget(system))
            rate = space.markings / seconds
            warm = median_time(lambda: explore(system, event_seeds=seeds), repeats)
            warm_rate = space.markings / warm
            base = baseline_explore(system, event_seeds=seeds, deadline=args.deadline)
            if base.finished:
                assert (base.markings, base.edges) == (space.markings, space.edges), "baseline disagrees"
                base_rate = base.markings / base.seconds
                base_cells = [f"{base.seconds:.3f}", f"{base_rate / 1e3:.1f} k", f"{rate / base_rate:.0f}x"]
                ratio_cell = verdict(rate / base_rate >= TARGET_RATIO)
            else:
                base_cells = [f"> {args.deadline:g} (stopped)", f"{base.markings / base.seconds / 1e3:.1f} k (partial)", "-"]
                ratio_cell = "n/a"
            rows.append(label + [f"{space.markings:,}", f"{space.edges:,}", f"{seconds:.4f}", f"{rate / 1e6:.2f} M",
                                 f"{warm_rate / 1e6:.2f} M"] + base_cells
                        + [f"{verdict(rate >= TARGET_RATE)} / {verdict(warm_rate >= TARGET_RATE)}", ratio_cell])
            print(" | ".join(map(str, rows[-1])), flush=True)
    print(f"\n(b) throughput, stable markings per second; {pinned}; target >= {TARGET_RATE / 1e6:g} M/s "
          f"and >= {TARGET_RATIO:g}x baseline (ratio where the baseline finished in {args.deadline:g} s)\n")
    print(table(
        ["system", "event seeds", "markings", "edges", "ours s", "ours /s", "ours /s memoised",
         "baseline s", "baseline /s", "ratio", ">= 2 M/s (rebuilt / memoised)", ">= 10x"],
        rows,
    ))


if __name__ == "__main__":
    main()
