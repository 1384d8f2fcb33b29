"""Prediction requests flooding a predictor: fresh predictions before and during (issue 14; SPEC §7).

A router with the shipped access control (``docker/zenoh/router.json5``), a
monitor and a predictor logged in as their users, and the paper's mission sent as
the bridge, 10 events/s; the monitor keeps one prediction (so each new marking
needs a query).  For each phase: how many of the monitor's steps got a fresh
(predicted) UnsafeReport within 1 s.  Phases, in one run:

- *quiet*: no flood;
- *observer flood*: 8 threads of another process send valid PredictRequests (and
  requests for unknown digests) as fast as they can, logged in as ``observer``:
  the router drops them (ACL), so nothing should change;
- *monitor-user flood*: the same logged in as a user allowed to ask (what an
  ACL cannot stop): the predictor's own bound (``--max-pending``, ``busy``
  answers) is what is left.

Target: the observer flood leaves fresh predictions as in the quiet phase
(at least 95 % of them).

    python benchmarks/bench_flood.py [--seconds 8]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time

from common import ROOT, table, verdict

import zenoh  # noqa: E402

from bench_latency import events  # noqa: E402
from services.monitor import start_monitor  # noqa: E402
from services.predictor import start_predictor  # noqa: E402
from skinet.files import load_system  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import decode, encode  # noqa: E402
from skinet.wire.convert import bundle, statuses  # noqa: E402
from skinet.wire.messages import LiveState, PredictRequest, UnsafeReport  # noqa: E402

sys.path.insert(0, str(ROOT / "tests" / "deploy"))
from deploy_support import acl_router_config, free_port, login, login_config, passwords  # noqa: E402


def flood(endpoint: str, user: str, password: str, seconds: float, threads: int = 8) -> None:
    """The flooder process: valid and unknown-digest requests, as fast as possible."""
    config = login_config(endpoint, user, password)
    session = zenoh.open(config)
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    digest = bundle(system).digest
    sent = [0]
    end = time.monotonic() + seconds

    def run(k: int) -> None:
        n = 0
        while time.monotonic() < end:
            n += 1
            d = digest if n % 2 else f"{k:02d}{n:030d}"[-32:]
            req = PredictRequest(system=system.name, digest=d, seq=n, budget=1.0,
                                 skillsets=statuses(system, system.initial_marking()))
            list(session.get(keys.predict(system.name), payload=encode(req), timeout=2.0))
            sent[0] += 1

    workers = [threading.Thread(target=run, args=(k,)) for k in range(threads)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    print(sent[0])
    session.close()


class Fresh:
    """Arrival of each LiveState and of fresh UnsafeReports, per step seq."""

    def __init__(self, session: zenoh.Session):
        self.states: dict[int, float] = {}
        self.fresh: list[tuple[float, int]] = []
        self._lock = threading.Lock()
        self._subs = [session.declare_subscriber(keys.state("spot_arm"), self._state),
                      session.declare_subscriber(keys.unsafe("spot_arm"), self._unsafe)]

    def _state(self, s: zenoh.Sample) -> None:
        m = decode(s.payload.to_bytes(), LiveState)
        with self._lock:
            self.states[m.seq] = time.monotonic()

    def _unsafe(self, s: zenoh.Sample) -> None:
        m = decode(s.payload.to_bytes(), UnsafeReport)
        if not m.prediction_stale:
            with self._lock:
                self.fresh.append((time.monotonic(), m.seq))

    def count(self, start: float, end: float) -> tuple[int, int]:
        """(steps published in [start, end), those with a fresh report for them within 1 s)."""
        with self._lock:
            steps = {seq: t for seq, t in self.states.items() if start <= t < end}
            got = {seq for t, seq in self.fresh if seq in steps and t - steps[seq] <= 1.0}
        return len(steps), len(got)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--flood":
        flood(sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5]))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0)
    args = ap.parse_args()

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(acl_router_config(endpoint))
    sessions = {u: login(endpoint, u) for u in ("monitor", "predictor", "bridge", "observer")}
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    predictor = start_predictor(sessions["predictor"], "bench")
    monitor = start_monitor(sessions["monitor"], system, budget=0.3, prediction_cache=1)
    fresh = Fresh(sessions["observer"])
    feed = events(int(3 * args.seconds * 10) + 20)
    position = [0]

    def play(seconds: float) -> tuple[float, float]:
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            key, payload = feed[position[0]]
            sessions["bridge"].put(key, payload)
            position[0] += 1
            time.sleep(0.1)
        time.sleep(1.2)
        return start, start + seconds

    rows = []
    results = {}
    try:
        time.sleep(1.0)
        for phase, user in (("quiet", None), ("observer flood", "observer"), ("monitor-user flood", "monitor")):
            flooder = None
            if user is not None:
                flooder = subprocess.Popen([sys.executable, __file__, "--flood", endpoint, user, passwords()[user],
                                            str(args.seconds + 1)], stdout=subprocess.PIPE, text=True)
                time.sleep(0.5)
            window = play(args.seconds)
            sent = flooder.communicate(timeout=60)[0].strip() if flooder else "-"
            steps, got = fresh.count(*window)
            results[phase] = (steps, got)
            rows.append([phase, f"{got}/{steps}", sent])
    finally:
        monitor.close()
        predictor.close()
        for s in sessions.values():
            s.close()
        router.close()

    print(f"## Prediction floods ({args.seconds:g} s per phase, 10 events/s)\n")
    print(table(["phase", "steps with a fresh prediction within 1 s", "flood requests sent"], rows))
    (qs, qg), (os_, og) = results["quiet"], results["observer flood"]
    ok = og / max(os_, 1) >= 0.95 * qg / max(qs, 1)
    print()
    print(table(["figure", "value", "target", ""], [
        ["fresh during the observer flood vs quiet", f"{og}/{os_} vs {qg}/{qs}", ">= 95 % of quiet", verdict(ok)],
        ["predictor counts", json.dumps(dict(predictor.counts)), "-", ""],
    ]))


if __name__ == "__main__":
    main()
