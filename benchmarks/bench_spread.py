"""(e) Predictor load spreading: share of the queries per instance and latency (docs/semantics.md §7).

A loopback router, N ``python -m services.predictor`` processes (default options:
2 worker threads, 8 pending) and, in this process, ``--clients`` monitors' prediction
clients (:class:`services.monitor.prediction.PredictionClient`, each on its own
client session, as robots sharing one off-board pool).  Every client wants a new
prediction every ``--period`` seconds (steady, open-loop load; a marking wanted
while the client's query is in flight replaces the previous one, as in the
monitor).  The system is three Spots and three arms from ``skillsets/`` explored
from a marking with the arms moving (``--pairs``), tens of milliseconds per
prediction.  Latency: from ``want`` to the reply, for every answered marking.

Rows, all in the same run:

- *1 instance*: the pool of one;
- *2 instances, shared key*: what every monitor did before load spreading (the
  router gives every query on ``skinet/<system>/predict/<client>`` to the same instance);
- *2 instances, spread*: per-instance keys, least outstanding then least recent.

The machine's cores are shared with whatever else runs (on the development machine,
other engineers' builds and tests): the figures are what this run saw, printed with
the load average; two instances can only help while a second core is free.

    python benchmarks/bench_spread.py [--clients 4] [--period 0.05] [--seconds 20]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from bench_latency import wait_token
from common import table

import zenoh  # noqa: E402

from services.common.zenoh_config import session_config  # noqa: E402
from services.monitor.prediction import PredictionClient  # noqa: E402
from skinet.system.load import load_system
from skinet.system.model import Marking, System  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import encode  # noqa: E402
from skinet.wire.convert import bundle, marking_of  # noqa: E402
from skinet.wire.messages import SkillsetStatus  # noqa: E402
from tests.loopback import client_args, free_endpoint  # noqa: E402
from tests.processes import start_module, start_skinet, stop_all  # noqa: E402
from tests.services.test_monitor import _heavy_system  # noqa: E402  (the system files)


def fleet_system(folder: Path, pairs: int) -> tuple[System, Marking]:
    """``pairs`` Spots and arms (renamed copies of the paper's skillsets), arms moving."""
    system = load_system(_heavy_system(folder, pairs))[0]
    moving = {f"arm{i}": SkillsetStatus(resources={"mutex": "Busy", "arm_status": "Away"}, running=["arm_ready"])
              for i in range(1, pairs + 1)}
    return system, marking_of(system, moving)


class Client:
    """One monitor's prediction client under a steady load; latencies of answered markings."""

    def __init__(self, endpoint: str, system: System, marking: Marking, spread: list[str]):
        self.session = zenoh.open(session_config("client", [endpoint], multicast_scouting=False))
        self.marking, self.wanted_at, self.latencies = marking, {}, []
        self._lock = threading.Lock()
        self.pc = PredictionClient(self.session, system, bundle(system).digest, self._on_reply,
                                   budget=2.0, timeout=5.0, retry=0.2)
        for name in spread:
            self.pc.instance(keys.alive(keys.ANY_SYSTEM, "predictor", name), True)

    def want(self, n: int) -> None:
        with self._lock:
            self.wanted_at[n] = time.perf_counter()
        self.pc.want((n,), self.marking)

    def _on_reply(self, key: tuple[int, ...], _reply: object) -> None:
        now = time.perf_counter()
        with self._lock:
            self.latencies.append(now - self.wanted_at[key[0]])

    def close(self) -> None:
        self.pc.close()
        self.session.close()


def open_when_up(endpoint: str, timeout: float = 30.0) -> zenoh.Session:
    """A client session, once the router (a process starting meanwhile) listens."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return zenoh.open(session_config("client", [endpoint], multicast_scouting=False))
        except zenoh.ZError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


def run(endpoint: str, system: System, marking: Marking, names: list[str], spread: bool,
        clients: int, period: float, seconds: float) -> list[object]:
    fleet = [Client(endpoint, system, marking, names if spread else []) for _ in range(clients)]
    try:
        for c in fleet:  # warm-up: every instance has fetched the model
            for k in range(len(names)):
                c.want(-1 - k)
                deadline = time.monotonic() + 10
                while c.pc.snapshot().answered < k + 1 and time.monotonic() < deadline:
                    time.sleep(0.01)
        base = [c.pc.snapshot() for c in fleet]
        for c in fleet:
            c.latencies.clear()
        start, n = time.perf_counter(), 0
        while time.perf_counter() - start < seconds:
            for c in fleet:
                c.want(n)
            n += 1
            time.sleep(max(0.0, start + n * period - time.perf_counter()))
        time.sleep(1.0)  # the last queries in flight
        after = [c.pc.snapshot() for c in fleet]
    finally:
        for c in fleet:
            c.close()
    answers = {name: sum(a.answers.get(name, 0) - b.answers.get(name, 0) for a, b in zip(after, base))
               for name in names}
    total = sum(answers.values())
    lat = sorted(x for c in fleet for x in c.latencies)
    failed = sum(a.failed - b.failed for a, b in zip(after, base))
    share = " / ".join(f"{name} {100 * v / total:.0f}%" for name, v in answers.items()) if total else "-"
    p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))] if lat else float("nan")
    label = f"{len(names)} instance{'s' if len(names) > 1 else ''}" + (", spread" if spread else ", shared key")
    return [label, total, f"{total / seconds:.1f}", share, failed,
            f"{1000 * statistics.median(lat):.0f}" if lat else "-", f"{1000 * p99:.0f}"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=4, help="monitors sharing the pool (default 4)")
    ap.add_argument("--period", type=float, default=0.05, help="seconds between wanted markings per client")
    ap.add_argument("--seconds", type=float, default=20.0, help="measured seconds per row (default 20)")
    ap.add_argument("--pairs", type=int, default=2, help="Spot+arm pairs in the system (default 2)")
    args = ap.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench-spread-"))
    system, marking = fleet_system(folder, args.pairs)
    endpoint = free_endpoint()
    zargs = client_args(endpoint)
    router = start_skinet("router", "--listen", endpoint, "--no-auth")  # loopback only
    procs: list[subprocess.Popen] = [router]
    rows = []
    try:
        watcher = open_when_up(endpoint)
        served = watcher.declare_queryable(keys.model(system.name, bundle(system).digest),
                                           lambda q: (q.reply(q.key_expr, encode(bundle(system))), q.drop()))
        for count, spread in ((1, True), (2, False), (2, True)):
            names = [f"i{k}" for k in range(1, count + 1)]
            pool = [start_module("services.predictor", "--instance", name, *zargs) for name in names]
            procs += pool
            for name in names:
                wait_token(watcher, keys.alive(keys.ANY_SYSTEM, "predictor", name), timeout=20)
            load = os.getloadavg()[0]
            rows.append(run(endpoint, system, marking, names, spread, args.clients, args.period, args.seconds)
                        + [f"{load:.1f}"])
            stop_all(pool, timeout=10)
        served.undeclare()
        watcher.close()
    finally:
        stop_all(procs)
    print(f"{args.clients} clients, one new marking each every {1000 * args.period:.0f} ms, {args.seconds:.0f} s "
          f"per row; system {system.name} ({args.pairs} Spot+arm pairs); {os.cpu_count()} CPUs, shared")
    print(table(["pool", "answered", "per s", "share", "failed", "p50 ms", "p99 ms", "load avg"], rows))


if __name__ == "__main__":
    main()
