"""Incident bundles: size per minute of the paper's mission and the cost of verifying one (docs/performance.md).

Plays the paper's unassisted run through the whole chain (simulated managers,
CDR, bridge, monitor, predictor) at its recorded pace divided by ``--speed``
(default 1: real time, about two minutes) while ``skinet record --bundle``
writes it, then ``skinet replay BUNDLE --verify`` re-runs it.  Prints the
bundle's size, its size per minute of mission, the plain MCAP monitor log of
the same run (``skinet record -o LOG.mcap``, the baseline, recorded at the same
time) and the verification's time.

    python benchmarks/bench_bundle.py [--speed 1]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, table

from chains.chain import run_chain  # noqa: E402
from skinet.system.load import load_system, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import parse_scenario  # noqa: E402
from tests.loopback import client_args, free_endpoint, open_client, open_router  # noqa: E402
from tests.processes import start_skinet, stop_all  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--speed", type=float, default=1.0, help="time scale of the run (default: 1, real time)")
    args = parser.parse_args()
    endpoint = free_endpoint()
    router = open_router(endpoint)
    path = ROOT / "skillsets" / "missions" / "unassisted.toml"
    scenario = parse_scenario(read_text(path), str(path))
    system, _ = load_system(path.parent / scenario.system)
    with tempfile.TemporaryDirectory() as tmp:
        bundle, log = Path(tmp) / "run.mcap", Path(tmp) / "log.mcap"
        procs = [start_skinet("record", "spot_arm", *out, *client_args(endpoint), log=sys.stdout)
                 for out in (["--bundle", str(bundle)], ["-o", str(log)])]
        time.sleep(2.0)  # the recorders subscribed (a benchmark: a missed first step only shrinks the baseline)
        session = open_client(endpoint)
        started = time.monotonic()
        run_chain(system, load_typemap(path.parent / scenario.system), scenario, session=session, speed=args.speed)
        minutes = (time.monotonic() - started) / 60
        session.close()
        stop_all(procs, timeout=60)
        t0 = time.monotonic()
        verified = subprocess.run([sys.executable, "-m", "skinet_cli.main", "replay", str(bundle), "--verify"],
                                  cwd=ROOT, capture_output=True, text=True)
        verify_s = time.monotonic() - t0
        size, base = bundle.stat().st_size, log.stat().st_size
    router.close()
    print(f"\nthe paper's unassisted run at speed {args.speed:g}: {minutes:.2f} min of mission")
    print(table(["file", "KB", "KB per minute", "verify"], [
        ["plain MCAP monitor log (skinet record -o, baseline)", f"{base / 1e3:.1f}", f"{base / 1e3 / minutes:.1f}", ""],
        ["incident bundle (skinet record --bundle)", f"{size / 1e3:.1f}", f"{size / 1e3 / minutes:.1f}",
         f"{verified.stdout.strip().splitlines()[-1] if verified.stdout else verified.stderr.strip()}, "
         f"{verify_s:.1f} s"]]))


if __name__ == "__main__":
    main()
