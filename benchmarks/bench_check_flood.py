"""Hostile command checks against the monitor's event path (issue 25 item 6; docs/semantics.md §7).

One peer session holds the monitor and a bridge stand-in (``tests/bridge_side.py``);
events of the paper's mission go to the monitor one at a time, every 5 ms, and the
latency event -> Verdicts is measured while four threads ask the command check as
fast as they can (no rate limit).  Phases, in one run:

- *quiet*: no checks (the baseline);
- *10 MB names*: each request a ``CheckRequest`` whose transition is a 10 MB name:
  refused before it is decoded (over 4096 bytes);
- *4 KB names*: requests just under the limit, with unknown names of 4 KB: decoded,
  answered without suggestions (names over 128 characters get none), outside the lock;
- *baseline*: the 10 MB requests answered as before this issue: decoded (no size
  limit), close names computed by difflib for any length and inside the monitor's
  lock (the same monitor, its limit lifted and its ``Checker.unknown`` wrapped so:
  a baseline measured in the same run).

Printed: verdict p50/p99/max per phase, requests answered per phase, and the
process's peak RSS.  Target: p99 under the two floods <= max(2 x quiet p99, 5 ms).

    python benchmarks/bench_check_flood.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import difflib
import logging
import resource
import statistics
import threading
import time
from collections.abc import Callable

from common import ROOT, table, verdict

import msgpack  # noqa: E402
import zenoh  # noqa: E402

from bench_latency import Arrivals, events, ping_pong  # noqa: E402
from services.common.zenoh_config import session_config  # noqa: E402
from services.monitor import service, start_monitor  # noqa: E402
from services.monitor.check import MAX_REQUEST  # noqa: E402
from skinet.system.load import load_system
from skinet.wire import keys  # noqa: E402
from skinet.wire.messages import CheckReply, CheckRequest  # noqa: E402
from tests.bridge_side import BridgeSide  # noqa: E402

THREADS = 4


def payload(name_bytes: int) -> bytes:
    return msgpack.packb({"v": 1, "skillset": "spot", "transition": "x" * name_bytes})


class Flood:
    """``THREADS`` threads asking the check with ``body`` until stopped; counts the answers."""

    def __init__(self, session: zenoh.Session, body: bytes):
        self.answered, self._stop = 0, threading.Event()
        key = keys.check("spot_arm", keys.LOCAL_CLIENT)

        def run() -> None:
            while not self._stop.is_set():
                for reply in session.get(key, payload=body, timeout=30.0):
                    if reply.ok is not None:
                        self.answered += 1

        self._threads = [threading.Thread(target=run) for _ in range(THREADS)]
        for t in self._threads:
            t.start()

    def stop(self) -> int:
        self._stop.set()
        for t in self._threads:
            t.join()
        return self.answered


def old_placement(monitor) -> Callable[[], None]:  # type: ignore[no-untyped-def]
    """Answer unknown names as before issue 25: any size decoded, difflib on the whole name, inside the
    monitor's lock; returns the function that puts things back."""
    checker, unknown = monitor.checker, monitor.checker.unknown
    service.MAX_REQUEST = 1 << 40

    def under_the_lock(request: CheckRequest) -> CheckReply | None:
        with monitor._lock:
            known = checker.transitions.get(request.skillset, [])
            if request.transition not in known:
                difflib.get_close_matches(request.transition, known, n=8, cutoff=0.6)
            return unknown(request)

    checker.unknown = under_the_lock

    def restore() -> None:
        checker.unknown, service.MAX_REQUEST = unknown, MAX_REQUEST

    return restore


def row(name: str, xs: list[float], answered: int | str) -> list[object]:
    q = statistics.quantiles(xs, n=100, method="inclusive")
    return [name, f"{statistics.median(xs) * 1e3:.2f}", f"{q[98] * 1e3:.2f}", f"{max(xs) * 1e3:.1f}", answered]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="length of each phase (default: 5)")
    args = ap.parse_args()
    logging.getLogger("skinet").setLevel(logging.ERROR)  # the refusals' warnings
    session = zenoh.open(session_config("peer", multicast_scouting=False))
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    monitor = start_monitor(session, system, check_rate_limit=0)
    side = BridgeSide(session, "spot_arm", source="bench", model=system)  # the monitor syncs from it
    payloads, position = events(int(5 * args.seconds / 0.005) + 100), [0]

    def latencies() -> list[float]:
        arrivals = Arrivals(session, keys.verdicts("spot_arm"))
        out: list[float] = []
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:
            out += ping_pong(lambda i: session.put(*payloads[position[0]], express=True), arrivals, 1, 0)
            position[0] += 1
            time.sleep(0.005)
        arrivals.close()
        return out

    rows, p99, peak_before = [], {}, 0.0
    try:
        for phase, body, old in (("quiet", None, False), ("10 MB names (refused undecoded)", payload(10 << 20), False),
                                 ("4 KB names (no suggestions, outside the lock)", payload(MAX_REQUEST - 64), False),
                                 ("baseline: 10 MB names decoded, difflib inside the lock", payload(10 << 20), True)):
            if old:
                peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            restore = old_placement(monitor) if old else None
            flood = Flood(session, body) if body is not None else None
            time.sleep(0.2 if flood else 0)
            xs = latencies()
            answered = flood.stop() if flood else "-"
            if restore:
                restore()
            rows.append(row(phase, xs, answered))
            p99[phase] = statistics.quantiles(xs, n=100, method="inclusive")[98]
        c = monitor.check_counters
    finally:
        side.close()
        monitor.close()
        session.close()
    print(f"## Hostile checks vs the monitor's events ({THREADS} threads asking, {args.seconds:g} s per phase)\n")
    print(table(["phase", "verdict p50 ms", "p99 ms", "max ms", "check answers"], rows))
    target = max(2 * p99["quiet"], 0.005)
    print()
    print(table(["figure", "value", "target", ""], [
        [name, f"{p99[name] * 1e3:.2f} ms", f"<= {target * 1e3:.2f} ms", verdict(p99[name] <= target)]
        for name in list(p99)[1:3]] + [
        ["refusals counted (oversized)", str(c.oversized), "-", ""],
        ["process peak RSS: before the baseline, after it",
         f"{peak_before:.0f} MB, {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB", "-", ""],
    ]))


if __name__ == "__main__":
    main()
