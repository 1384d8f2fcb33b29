"""(d) Start-up of ``skinet unsafe``: this tree against a baseline commit, same run.

Times ``skinet unsafe skillsets/spot_arm.toml`` end to end in fresh processes
(CPU time, user + system: wall time on the shared 2-core machine varies twofold;
least of ``--repeats`` runs, after one warm-up run that writes the .pyc files
and the lark tables; ``--no-bytecode`` compiles every module at every run, as
this sandbox's PYTHONDONTWRITEBYTECODE=1 does), and the import of ``skinet_cli.main`` alone.  The
baseline is a temporary ``git worktree`` of ``--baseline`` (default: the
commit before issue 10), run with the same interpreter, alternating with this
tree's runs.  This tree runs twice: with the lark tables cached (the usual
case, ``~/.cache/skinet-live``; here a temporary folder) and with an empty
cache every time (tables built, as every run did before).  Target: half the
baseline.

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
# The command line moved from skinet/cli/ to skinet_cli/ (issue 25): the baseline tree has the old one.
_MAIN = ("try:\n    from skinet_cli import main as cli\nexcept ImportError:\n"
         "    from skinet.cli import main as cli\n")
UNSAFE = _MAIN + "raise SystemExit(cli.main(['unsafe', 'skillsets/spot_arm.toml']))"
IMPORT = _MAIN


BYTECODE = True  # see --no-bytecode


def _run(tree: Path, code: str, cache: Path, pycache: Path) -> tuple[float, float]:
    """CPU seconds (user + system; steadier than wall time on a shared machine) and wall seconds of ``code``
    in a fresh interpreter."""
    env = dict(os.environ, PYTHONPATH=str(tree), XDG_CACHE_HOME=str(cache))
    if BYTECODE:  # .pyc files in a folder of their own: none written into the trees
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache / tree.name)
    else:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    t0 = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-c", code], cwd=tree, env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        raise SystemExit(f"bench_startup: {code!r} in {tree} exited with {child.returncode}")
    return usage.ru_utime + usage.ru_stime, time.perf_counter() - t0


def least(runs: list[tuple[Path, bool]], code: str, repeats: int, cache: Path) -> list[tuple[float, float]]:
    """Least CPU and least wall time of ``code`` in fresh interpreters for each ``(tree, cold)`` of ``runs``.

    The runs alternate, so that a change of the machine's load falls on all of them;
    ``cold``: an empty lark cache every time.  The first round (writing .pyc files and
    lark tables) is not counted.
    """
    best = [(float("inf"), float("inf"))] * len(runs)
    for i in range(repeats + 1):
        for k, (tree, cold) in enumerate(runs):
            cpu, wall = _run(tree, code, Path(tempfile.mkdtemp(dir=cache)) if cold else cache, cache / "pycache")
            if i:
                best[k] = (min(best[k][0], cpu), min(best[k][1], wall))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", default=BASELINE)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--no-bytecode", action="store_true",
                        help="compile every module at every run (PYTHONDONTWRITEBYTECODE, as in the sandbox)")
    args = parser.parse_args()
    global BYTECODE
    BYTECODE = not args.no_bytecode
    with tempfile.TemporaryDirectory(prefix="skinet-startup-") as tmp:
        cache = Path(tmp) / "cache"
        cache.mkdir()
        base = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", str(base), args.baseline], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            ((empty, empty_wall),) = least([(ROOT, False)], "pass", args.repeats, cache)
            rows = []
            for label, code in (("import skinet_cli.main", IMPORT), ("skinet unsafe spot_arm.toml", UNSAFE)):
                (theirs, theirs_wall), (ours, ours_wall), (cold, cold_wall) = least(
                    [(base, False), (ROOT, False), (ROOT, True)], code, args.repeats, cache)
                theirs, ours, cold = theirs - empty, ours - empty, cold - empty
                theirs_wall, ours_wall, cold_wall = theirs_wall - empty_wall, ours_wall - empty_wall, cold_wall - empty_wall
                rows.append([label, f"{theirs:.3f} ({theirs_wall:.3f})", f"{ours:.3f} ({ours_wall:.3f})",
                             f"{cold:.3f} ({cold_wall:.3f})", f"{theirs / ours:.2f}x", verdict(ours <= theirs / 2)])
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)
    print(f"\n(d) start-up, CPU seconds (wall seconds) beyond an empty interpreter ({empty:.3f} s CPU, "
          f"{empty_wall:.3f} s wall); least of {args.repeats}; "
          f"{'with' if BYTECODE else 'without'} .pyc files; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
          "cores\n")
    print(table(["run", f"baseline {args.baseline}", "this tree", "this tree, empty lark cache", "speed-up (CPU)",
                 "target (half)"], rows))


if __name__ == "__main__":
    main()
