"""(d) Start-up of ``skinet unsafe``: this tree against a baseline commit, same run.

Times ``skinet unsafe skillsets/spot_arm.toml`` end to end in fresh processes
(least of ``--repeats`` runs, after one warm-up run that fills the lark
cache), and the import of ``skinet.cli.main`` alone.  The baseline is a
temporary ``git worktree`` of ``--baseline`` (default: the commit before
issue 10), run with the same interpreter.  Target: half the baseline's imports.

    python benchmarks/bench_startup.py [--baseline REF] [--repeats 7]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, table, verdict

BASELINE = "a542d23"
UNSAFE = "from skinet.cli.main import main; raise SystemExit(main(['unsafe', 'skillsets/spot_arm.toml']))"
IMPORT = "import skinet.cli.main"


def least(tree: Path, code: str, repeats: int) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree))
    best = float("inf")
    for i in range(repeats + 1):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], cwd=tree, env=env, check=True, capture_output=True)
        if i:  # the first run fills caches (lark tables, .pyc files)
            best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", default=BASELINE)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    empty = least(ROOT, "pass", args.repeats)
    with tempfile.TemporaryDirectory(prefix="skinet-baseline-") as tmp:
        base = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", str(base), args.baseline], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            rows = []
            for label, code in (("import skinet.cli.main", IMPORT), ("skinet unsafe spot_arm.toml", UNSAFE)):
                ours, theirs = least(ROOT, code, args.repeats) - empty, least(base, code, args.repeats) - empty
                rows.append([label, f"{theirs:.3f}", f"{ours:.3f}", f"{theirs / ours:.2f}x", verdict(ours <= theirs / 2)])
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)
    print(f"\n(d) start-up, seconds beyond an empty interpreter ({empty:.3f} s); least of {args.repeats}; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    print(table(["run", f"baseline {args.baseline}", "this tree", "speed-up", "target (half)"], rows))


if __name__ == "__main__":
    main()
