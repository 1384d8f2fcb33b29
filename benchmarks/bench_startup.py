"""(d) Start-up of ``skinet unsafe`` and (e) of every service: this tree against a baseline commit, same run.

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

(e) ``python -m services.X --help`` for each service, against ``--services-baseline``
(default: main before issue 33 item 4, when every service imported the ROS type
library, rosbags, at start), with whether the process imported rosbags.

    python benchmarks/bench_startup.py [--baseline REF] [--services-baseline REF] [--repeats 7]
                                       [--only unsafe|services]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

from common import ROOT, table, verdict

BASELINE = "a542d23"
SERVICES_BASELINE = "a843b08"
SERVICES = ("bridge_ros2", "dashboard", "foxglove", "monitor", "pilot", "predictor", "secrets", "simulator")
# The command line moved from skinet/cli/ to skinet_cli/ (issue 25): the baseline tree has the old one.
_MAIN = ("try:\n    from skinet_cli import main as cli\nexcept ImportError:\n"
         "    from skinet.cli import main as cli\n")
UNSAFE = _MAIN + "raise SystemExit(cli.main(['unsafe', 'skillsets/spot_arm.toml']))"
IMPORT = _MAIN
# ``python -m services.X --help``, then whether the process imported the ROS type library.
ROSBAGS = ("import runpy, sys\nsys.argv = [{name!r}, '--help']\ntry:\n"
           "    runpy.run_module({name!r}, run_name='__main__', alter_sys=True)\nexcept SystemExit:\n"
           "    print(any(m.split('.')[0] == 'rosbags' for m in sys.modules))\n")

BYTECODE = True  # see --no-bytecode


def _run(tree: Path, argv: Sequence[str], cache: Path, pycache: Path) -> tuple[float, float]:
    """CPU seconds (user + system; steadier than wall time on a shared machine) and wall seconds of a fresh
    interpreter given ``argv`` (``-c CODE``, ``-m MODULE ARGS``)."""
    env = dict(os.environ, PYTHONPATH=str(tree), XDG_CACHE_HOME=str(cache))
    if BYTECODE:  # .pyc files in a folder of their own: none written into the trees
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache / tree.name)
    else:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    t0 = time.perf_counter()
    child = subprocess.Popen([sys.executable, *argv], cwd=tree, env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        raise SystemExit(f"bench_startup: {' '.join(argv)!r} in {tree} exited with {child.returncode}")
    return usage.ru_utime + usage.ru_stime, time.perf_counter() - t0


def least(runs: list[tuple[Path, bool]], argv: Sequence[str], repeats: int, cache: Path) -> list[tuple[float, float]]:
    """Least CPU and least wall time of fresh interpreters given ``argv`` for each ``(tree, cold)`` of ``runs``.

    The runs alternate, so that a change of the machine's load falls on all of them;
    ``cold``: an empty lark cache every time.  The first round (writing .pyc files and
    lark tables) is not counted.
    """
    best = [(float("inf"), float("inf"))] * len(runs)
    for i in range(repeats + 1):
        for k, (tree, cold) in enumerate(runs):
            cpu, wall = _run(tree, argv, Path(tempfile.mkdtemp(dir=cache)) if cold else cache, cache / "pycache")
            if i:
                best[k] = (min(best[k][0], cpu), min(best[k][1], wall))
    return best


@contextlib.contextmanager
def worktree(ref: str, folder: Path) -> Iterator[Path]:
    """A temporary ``git worktree`` of ``ref`` at ``folder``."""
    subprocess.run(["git", "worktree", "add", "--detach", str(folder), ref], cwd=ROOT, check=True, capture_output=True)
    try:
        yield folder
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(folder)], cwd=ROOT, capture_output=True)


def imports_rosbags(tree: Path, service: str) -> str:
    """``yes`` or ``no``: whether ``python -m services.X --help`` imports rosbags in ``tree``."""
    code = ROSBAGS.format(name=f"services.{service}")
    done = subprocess.run([sys.executable, "-c", code], cwd=tree, env=dict(os.environ, PYTHONPATH=str(tree)),
                          capture_output=True, text=True, check=True)
    return {"True": "yes", "False": "no"}[done.stdout.splitlines()[-1]]


def unsafe_rows(base: Path, repeats: int, cache: Path, empty: tuple[float, float]) -> list[list[str]]:
    """(d): ``import skinet_cli.main`` and ``skinet unsafe``, baseline, this tree, this tree with no lark cache."""
    rows = []
    for label, code in (("import skinet_cli.main", IMPORT), ("skinet unsafe spot_arm.toml", UNSAFE)):
        (theirs, theirs_wall), (ours, ours_wall), (cold, cold_wall) = least(
            [(base, False), (ROOT, False), (ROOT, True)], ["-c", code], repeats, cache)
        theirs, ours, cold = theirs - empty[0], ours - empty[0], cold - empty[0]
        theirs_wall, ours_wall, cold_wall = theirs_wall - empty[1], ours_wall - empty[1], cold_wall - empty[1]
        rows.append([label, f"{theirs:.3f} ({theirs_wall:.3f})", f"{ours:.3f} ({ours_wall:.3f})",
                     f"{cold:.3f} ({cold_wall:.3f})", f"{theirs / ours:.2f}x", verdict(ours <= theirs / 2)])
    return rows


def service_rows(base: Path, repeats: int, cache: Path, empty: tuple[float, float]) -> list[list[str]]:
    """(e): ``python -m services.X --help``, baseline against this tree, and whether each imports rosbags."""
    rows = []
    for service in SERVICES:
        (theirs, theirs_wall), (ours, ours_wall) = least([(base, False), (ROOT, False)],
                                                         ["-m", f"services.{service}", "--help"], repeats, cache)
        theirs, ours = theirs - empty[0], ours - empty[0]
        theirs_wall, ours_wall = theirs_wall - empty[1], ours_wall - empty[1]
        rows.append([f"services.{service} --help", f"{theirs:.3f} ({theirs_wall:.3f})", imports_rosbags(base, service),
                     f"{ours:.3f} ({ours_wall:.3f})", imports_rosbags(ROOT, service), f"{theirs - ours:+.3f}",
                     f"{theirs / ours:.2f}x"])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", default=BASELINE, help=f"baseline of (d) (default: {BASELINE})")
    parser.add_argument("--services-baseline", default=SERVICES_BASELINE,
                        help=f"baseline of (e) (default: {SERVICES_BASELINE})")
    parser.add_argument("--only", choices=("unsafe", "services"), help="run (d) or (e) only (default: both)")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--no-bytecode", action="store_true",
                        help="compile every module at every run (PYTHONDONTWRITEBYTECODE, as in the sandbox)")
    args = parser.parse_args()
    global BYTECODE
    BYTECODE = not args.no_bytecode
    with tempfile.TemporaryDirectory(prefix="skinet-startup-") as tmp:
        cache = Path(tmp) / "cache"
        cache.mkdir()
        ((empty, empty_wall),) = least([(ROOT, False)], ["-c", "pass"], args.repeats, cache)
        unsafe = services = None
        if args.only != "services":
            with worktree(args.baseline, Path(tmp) / "tree") as base:
                unsafe = unsafe_rows(base, args.repeats, cache, (empty, empty_wall))
        if args.only != "unsafe":
            with worktree(args.services_baseline, Path(tmp) / "services-tree") as base:
                services = service_rows(base, args.repeats, cache, (empty, empty_wall))
    head = (f"CPU seconds (wall seconds) beyond an empty interpreter ({empty:.3f} s CPU, {empty_wall:.3f} s wall); "
            f"least of {args.repeats}; {'with' if BYTECODE else 'without'} .pyc files; load average "
            f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    if unsafe is not None:
        print(f"\n(d) start-up, {head}")
        print(table(["run", f"baseline {args.baseline}", "this tree", "this tree, empty lark cache",
                     "speed-up (CPU)", "target (half)"], unsafe))
    if services is not None:
        print(f"\n(e) service start-up, {head}")
        print(table(["run", f"baseline {args.services_baseline}", "imports rosbags", "this tree", "imports rosbags",
                     "saved (CPU)", "speed-up (CPU)"], services))


if __name__ == "__main__":
    main()
