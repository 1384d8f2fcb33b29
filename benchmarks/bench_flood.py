"""Prediction requests flooding a predictor: fresh predictions before and during (issue 14; docs/semantics.md §7).

A router with the shipped access control (``docker/zenoh/router.json5``), a
monitor and a predictor logged in as their users, and the paper's mission sent as
the bridge, 10 events/s; the monitor keeps one prediction (so each new marking
needs a query).  For each phase: how many of the monitor's steps got a fresh
(predicted) UnsafeReport within 1 s.  Phases, in one run:

- *quiet*: no flood;
- *observer flood*: 16 threads of another process send valid PredictRequests (and
  requests for unknown digests) as fast as they can, logged in as ``observer``:
  the router drops them (ACL), so nothing should change;
- *other client, limit on*: the same logged in as ``flooder``, a second user
  allowed to ask predictions under its own name (what an ACL cannot stop); the
  predictor's per-client rate limit (``--rate-limit``, default 20/s) refuses the
  excess at once, and a client holds at most half of ``--max-pending``;
- *other client, limit off*: the same against a predictor started with
  ``--rate-limit 0`` (the contrast; a client's share of ``--max-pending``, half of
  it, still applies).

On 2 shared cores the flooding process itself takes CPU from the monitor and the
router: compare each phase with the observer flood, whose requests the router
drops before any service sees them.

Targets: the observer flood and the other client's flood with the limit on leave
fresh predictions as in the quiet phase (at least 95 % of them).

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
from tests.bridge_side import BridgeSide  # noqa: E402
from services.predictor import start_predictor  # noqa: E402
from skinet.system.load import load_system
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import decode, encode  # noqa: E402
from skinet.wire.convert import bundle, statuses  # noqa: E402
from skinet.wire.messages import LiveState, PredictReply, PredictRequest, UnsafeReport  # noqa: E402

sys.path.insert(0, str(ROOT / "tests" / "deploy"))
from deploy_support import acl_router_config, free_port, login, login_config, passwords  # noqa: E402


def flood(endpoint: str, user: str, password: str, seconds: float, threads: int = 16) -> None:
    """The flooder process: valid and unknown-digest requests, as fast as possible."""
    config = login_config(endpoint, user, password)
    session = zenoh.open(config)
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    digest = bundle(system).digest
    sent = [0]
    answers: dict[str, int] = {}
    end = time.monotonic() + seconds

    def run(k: int) -> None:
        n = 0
        while time.monotonic() < end:
            n += 1
            d = digest if n % 2 else f"{k:02d}{n:030d}"[-32:]
            req = PredictRequest(system=system.name, digest=d, seq=n, budget=1.0,
                                 skillsets=statuses(system, system.initial_marking()))
            for reply in session.get(keys.predict(system.name, user), payload=encode(req), timeout=2.0):
                kind = "error reply" if reply.ok is None else _kind(reply.ok.payload.to_bytes())
                answers[kind] = answers.get(kind, 0) + 1
            sent[0] += 1

    workers = [threading.Thread(target=run, args=(k,)) for k in range(threads)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    print(json.dumps({"sent": sent[0], "answers": answers}))
    session.close()


def _kind(payload: bytes) -> str:
    reply = decode(payload, PredictReply)
    if reply.ok:
        return "ok"
    for kind in ("rate limited", "busy", "cannot fetch model"):
        if reply.error.startswith(kind):
            return kind
    return reply.error[:40]


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
    router = zenoh.open(acl_router_config(endpoint, askers=("flooder",)))
    sessions = {u: login(endpoint, u) for u in ("monitor", "predictor", "bridge", "observer")}
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    predictor = start_predictor(sessions["predictor"], "bench")
    monitor = start_monitor(sessions["monitor"], system, budget=0.3, prediction_cache=1, client="monitor")
    fresh = Fresh(sessions["observer"])
    side = BridgeSide(sessions["bridge"], "spot_arm", source="bench", model=system)  # the monitor syncs from it
    feed = events(int(4 * args.seconds * 10) + 20)
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
    counts = {}
    try:
        time.sleep(1.0)
        for phase, user in (("quiet", None), ("observer flood", "observer"), ("other client, limit on", "flooder"),
                            ("other client, limit off", "flooder")):
            if phase.endswith("limit off"):
                counts["limit on"] = dict(predictor.counts)
                predictor.close()
                predictor = start_predictor(sessions["predictor"], "bench-nolimit", rate_limit=0)
                time.sleep(0.5)
            flooder = None
            if user is not None:
                flooder = subprocess.Popen([sys.executable, __file__, "--flood", endpoint, user, passwords()[user],
                                            str(args.seconds + 1)], stdout=subprocess.PIPE, text=True)
                time.sleep(0.5)
            window = play(args.seconds)
            out = json.loads(flooder.communicate(timeout=60)[0]) if flooder else {"sent": "-", "answers": {}}
            steps, got = fresh.count(*window)
            results[phase] = (steps, got)
            answered = ", ".join(f"{k}: {v}" for k, v in sorted(out["answers"].items())) or "none (ACL)"
            rows.append([phase, f"{got}/{steps}", out["sent"], answered if flooder else "-"])
    finally:
        monitor.close()
        side.close()
        predictor.close()
        for s in sessions.values():
            s.close()
        router.close()

    print(f"## Prediction floods ({args.seconds:g} s per phase, 10 events/s)\n")
    print(table(["phase", "monitor steps with a fresh prediction within 1 s", "flood requests sent",
                 "flood answers"], rows))
    (qs, qg) = results["quiet"]

    def near_quiet(phase: str) -> tuple[str, bool]:
        s_, g = results[phase]
        return f"{g}/{s_} vs {qg}/{qs}", g / max(s_, 1) >= 0.95 * qg / max(qs, 1)

    print()
    print(table(["figure", "value", "target", ""], [
        ["fresh during the observer flood vs quiet", *near_quiet("observer flood")[:1], ">= 95 % of quiet",
         verdict(near_quiet("observer flood")[1])],
        ["fresh during another client's flood, limit on, vs quiet", near_quiet("other client, limit on")[0],
         ">= 95 % of quiet", verdict(near_quiet("other client, limit on")[1])],
        ["fresh during another client's flood, limit off, vs quiet", near_quiet("other client, limit off")[0],
         "(contrast)", ""],
        ["predictor counts, limit on", json.dumps(counts.get("limit on", {})), "-", ""],
        ["predictor counts, limit off", json.dumps(dict(predictor.counts)), "-", ""],
    ]))


if __name__ == "__main__":
    main()
