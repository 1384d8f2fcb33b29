"""A hostile model against an embedded ``skinet run`` (issue 14; SPEC §6, §7).

Monitor and predictor share one peer session, as in ``skinet run``.  An attacker on
the same session serves the consistent 1.9 KB bundle of
``tests/services/hostile.py`` (ten resources, ten skills, 2^10 DNF clauses per
guard, seconds to build) and asks for predictions of it with ``budget=0.1``, again and again, while
events of the paper's mission are sent to the monitor one at a time, every 5 ms,
and the latency event -> Verdicts is measured.  Phases, in one run:

- *quiet*: no attack (the baseline);
- *isolated*: the attack against our predictor (worker processes with a memory
  limit, killed at budget + grace);
- *in-process peer*: what building the same model does to the monitor when it
  runs on a thread of the monitor's process, as the predictor did before.

Printed: verdict p50/p99/max per phase, the predictor's peak memory (its process,
which here also holds the monitor, and its largest worker) against the limit, and
how many hostile requests were answered and how fast.  Targets: p99 under attack
<= max(2 x quiet p99, 5 ms); worker peak <= the limit; every hostile request
answered within budget + grace + 1 s (plus a replacement's start-up).

    python benchmarks/bench_hostile.py [--seconds 10] [--memory-mb 512]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import threading
import time
from pathlib import Path

from common import ROOT, table, verdict

import zenoh  # noqa: E402

from bench_latency import Arrivals, events, ping_pong  # noqa: E402
from services.common.zenoh_config import session_config  # noqa: E402
from services.monitor import start_monitor  # noqa: E402
from services.predictor import start_predictor  # noqa: E402
from skinet.files import load_system  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.convert import system_from_bundle  # noqa: E402
from tests.bridge_side import BridgeSide  # noqa: E402
from tests.services.hostile import Attacker, hostile_bundle  # noqa: E402

GRACE = 1.0


def vm_hwm_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class Feed:
    """The mission's events, numbered on across phases (a restarted count would be duplicates)."""

    def __init__(self, n: int):
        self.payloads, self.next = events(n), 0

    def latencies(self, session: zenoh.Session, seconds: float, gap: float = 0.005) -> list[float]:
        """Event -> Verdicts latency of one event every ``gap`` s for ``seconds`` (a robot's pace)."""
        arrivals = Arrivals(session, keys.verdicts("spot_arm"))
        out: list[float] = []
        end = time.monotonic() + seconds
        try:
            while time.monotonic() < end:
                out += ping_pong(lambda i: session.put(*self.payloads[self.next], express=True), arrivals, 1, 0)
                self.next += 1
                time.sleep(gap)
            return out
        finally:
            arrivals.close()


def row(name: str, xs: list[float]) -> list[object]:
    q = statistics.quantiles(xs, n=100, method="inclusive")
    return [name, f"{statistics.median(xs) * 1e3:.2f}", f"{q[98] * 1e3:.2f}", f"{max(xs) * 1e3:.1f}"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="length of each phase (default: 10)")
    ap.add_argument("--memory-mb", type=int, default=512)
    args = ap.parse_args()

    config = session_config("peer", listen=["tcp/127.0.0.1:0"], multicast_scouting=False)
    config.insert_json5("scouting/delay", "0")
    session = zenoh.open(config)
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    t0 = time.monotonic()
    predictor = start_predictor(session, "bench", memory_mb=args.memory_mb, grace=GRACE)
    startup = time.monotonic() - t0
    monitor = start_monitor(session, system, budget=0.5)
    side = BridgeSide(session, "spot_arm", source="bench", model=system)  # the monitor syncs from it first
    rows = []
    feed = Feed(int(3 * args.seconds / 0.005) + 100)
    try:
        quiet = feed.latencies(session, args.seconds)
        rows.append(row("quiet", quiet))

        attacker = Attacker(session)
        stop = threading.Event()
        answers: list[tuple[float, str]] = []

        def attack() -> None:
            n = 0
            while not stop.is_set():
                n += 1
                t = time.monotonic()
                replies = attacker.ask(budget=0.1, seq=n, timeout=60)
                answers.append((time.monotonic() - t, "reply" if replies else "none"))

        attacking = threading.Thread(target=attack)
        attacking.start()
        time.sleep(0.5)  # the first hostile job is running
        isolated = feed.latencies(session, args.seconds)
        stop.set()
        attacking.join()
        attacker.close()
        rows.append(row("isolated (our predictor)", isolated))

        small = hostile_bundle()
        building = threading.Thread(target=lambda: system_from_bundle(small))
        building.start()
        inproc = feed.latencies(session, 3.0)  # about the build's length
        building.join()
        rows.append(row("in-process peer (the same model built on a thread)", inproc))
    finally:
        monitor.close()
        side.close()
        predictor.close()
        session.close()

    print(f"## Hostile model vs. a co-located monitor ({len(quiet)}, {len(isolated)}, {len(inproc)} events)\n")
    print(table(["phase", "verdict p50 ms", "p99 ms", "max ms"], rows))
    q99 = lambda xs: statistics.quantiles(xs, n=100, method="inclusive")[98]  # noqa: E731
    target = max(2 * q99(quiet), 0.005)
    worker_peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    slowest = max(t for t, _ in answers)
    bound = 0.1 + GRACE + 1.0 + 2 * startup
    print()
    print(table(["figure", "value", "target", ""], [
        ["verdict p99 under attack", f"{q99(isolated) * 1e3:.2f} ms", f"<= {target * 1e3:.2f} ms",
         verdict(q99(isolated) <= target)],
        ["predictor process peak RSS (holds the monitor too)", f"{vm_hwm_mb():.0f} MB", "-", ""],
        ["largest worker's peak RSS", f"{worker_peak:.0f} MB", f"<= {args.memory_mb} MB (RLIMIT_AS)",
         verdict(worker_peak <= args.memory_mb)],
        ["hostile requests answered", f"{sum(a == 'reply' for _, a in answers)}/{len(answers)}", "all",
         verdict(all(a == "reply" for _, a in answers))],
        ["slowest hostile answer", f"{slowest:.2f} s", f"<= {bound:.2f} s (budget + grace + 1 s + restart)",
         verdict(slowest <= bound)],
        ["workers killed", str(predictor.counts["killed"]), "-", ""],
    ]))


if __name__ == "__main__":
    main()
