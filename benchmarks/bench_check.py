"""Command check latency: ``skinet/<system>/check`` request -> reply (docs/semantics.md §7).

The monitor sits at the paper's warning marking (arm at RD, a fresh prediction
from an in-process predictor), so every answer carries a reason.  Rows:

- in-process, ``Monitor.check`` (the lock and the answer from the live Algorithm 1
  result) and the queryable's whole work (decode the request, answer, encode);
- in-process through Zenoh: ``get`` on the monitor's own peer session;
- through a router: the monitor runs as ``python -m services.monitor`` (client
  mode), this process asks through a loopback router.

Baselines measured in the same run: recomputing Algorithm 1 with the prediction
for every question (what a check without the monitor's live state would cost),
and a raw Zenoh ``get`` -> empty reply in the same topology.  Targets: p99 <= 1 ms
in-process, p99 <= 5 ms through a router.

    python benchmarks/bench_check.py [--n 3000]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

from common import table, verdict

import zenoh  # noqa: E402

from chains.chain import embedded_services  # noqa: E402
from services.monitor.check import request_from  # noqa: E402
from skinet.system.load import load_system
from skinet.system.live import LiveSystem  # noqa: E402
from skinet.verify.algorithm1 import analyse  # noqa: E402
from skinet.verify.predict import forecast  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import decode, encode  # noqa: E402
from skinet.system.model import System  # noqa: E402
from skinet.wire.messages import CheckReply, CheckRequest  # noqa: E402
from tests.bridge_side import BridgeSide  # noqa: E402
from tests.loopback import client_args, loopback_router  # noqa: E402
from tests.processes import start_module, stop  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SYSTEM_FILE = ROOT / "skillsets" / "spot_arm.toml"
TO_WARNING = [("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
              ("spot", "stand_up.success.standing"), ("manipulator", "arm_ready.start"),
              ("manipulator", "arm_ready.success.ready")]
REQUEST = CheckRequest(skillset="spot", transition="go_to_waypoint.start")


def timed(fn: Callable[[], object], n: int, warmup: int = 200) -> list[float]:
    out = []
    for i in range(warmup + n):
        t0 = time.perf_counter()
        fn()
        if i >= warmup:
            out.append(time.perf_counter() - t0)
    return out


def row(name: str, samples: list[float], target: float | None) -> list[object]:
    q = statistics.quantiles(samples, n=100, method="inclusive")
    p99 = q[98]
    return [name, f"{statistics.median(samples) * 1e6:.0f}", f"{p99 * 1e6:.0f}", f"{max(samples) * 1e6:.0f}",
            "-" if target is None else f"<= {target * 1e3:.0f} ms",
            "baseline" if target is None else verdict(p99 <= target)]


def get_once(session: zenoh.Session, key: str, payload: bytes) -> bytes:
    for reply in session.get(key, payload=payload, express=True):
        if reply.ok is not None:
            return reply.ok.payload.to_bytes()
    raise RuntimeError(f"no reply on {key}")


def send_events(session: zenoh.Session, system: System) -> BridgeSide:
    """The bridge's side (the monitor syncs from it), then the events up to the warning."""
    side = BridgeSide(session, system.name, source="bench", model=system)
    side.synced()
    for skillset, transition in TO_WARNING:
        side.send(skillset, transition)
    return side


def wait(predicate: Callable[[], bool], what: str, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise SystemExit(f"bench_check: timed out waiting for {what}")
        time.sleep(0.01)


def in_process(n: int) -> list[list[object]]:
    system, _ = load_system(SYSTEM_FILE)
    with embedded_services(None, system, True, check_rate_limit=0) as (session, monitor, _):  # one asker, unlimited
        side = send_events(session, system)
        wait(lambda: monitor.counters.applied == len(TO_WARNING) and not monitor.snapshot().unsafe.prediction_stale,
             "the warning marking with a fresh prediction")
        reply = monitor.check(REQUEST)
        assert reply.decision == "warn" and reply.reasons, reply
        payload = encode(REQUEST)

        def whole() -> bytes:
            request = request_from(system.name, payload, "")
            return encode(monitor.check(request))  # type: ignore[arg-type]

        live = LiveSystem(system)
        for skillset, transition in TO_WARNING:
            live.apply(skillset, transition)
        prediction = forecast(system, live.marking, budget=5.0)
        echo = session.declare_queryable("bench/echo", lambda q: (q.reply("bench/echo", b"y"), q.drop()))
        key = keys.check(system.name, keys.LOCAL_CLIENT)
        assert decode(get_once(session, key, payload), CheckReply).decision == "warn"
        rows = [
            row("in-process: Monitor.check", timed(lambda: monitor.check(REQUEST), n), 1e-3),
            row("in-process: decode + check + encode", timed(whole, n), 1e-3),
            row("in-process: Zenoh get on the monitor's session", timed(lambda: get_once(session, key, payload), n), 1e-3),
            row("baseline: Algorithm 1 recomputed per question", timed(
                lambda: analyse(system, live.marking, prediction), max(200, n // 10), 20), None),
            row("baseline: raw Zenoh get -> empty reply, same session", timed(
                lambda: get_once(session, "bench/echo", b"x"), n), None),
        ]
        echo.undeclare()
        side.close()
        return rows


def wait_for_monitor(session: zenoh.Session, system: str) -> None:
    """Until a monitor of ``system`` holds its liveliness token."""
    tokens: set[str] = set()
    sub = session.liveliness().declare_subscriber(keys.alive(system, "monitor", "*"),
                                                  lambda s: tokens.add(str(s.key_expr)), history=True)
    wait(lambda: bool(tokens), "the monitor process")
    sub.undeclare()


def through_router(n: int) -> list[list[object]]:
    endpoint, router, (client, other) = loopback_router(2)
    monitor = start_module("services.monitor", str(SYSTEM_FILE), *client_args(endpoint), "--log-level", "ERROR",
                           "--check-rate-limit", "0", log=sys.stderr)
    try:
        system = "spot_arm"
        wait_for_monitor(client, system)
        side = send_events(client, load_system(SYSTEM_FILE)[0])
        payload, key = encode(REQUEST), keys.check(system, keys.LOCAL_CLIENT)
        wait(lambda: decode(get_once(client, key, payload), CheckReply).seq == len(TO_WARNING), "the events applied")
        echo = other.declare_queryable("bench/echo", lambda q: (q.reply("bench/echo", b"y"), q.drop()))
        time.sleep(0.2)
        rows = [
            row("router: get skinet/<system>/check (monitor process)", timed(lambda: get_once(client, key, payload), n),
                5e-3),
            row("baseline: raw Zenoh get -> empty reply via the router", timed(
                lambda: get_once(client, "bench/echo", b"x"), n), None),
        ]
        echo.undeclare()
        side.close()
        return rows
    finally:
        stop(monitor, timeout=10)
        other.close()
        client.close()
        router.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=3000, help="questions per row (default: 3000)")
    args = parser.parse_args()
    rows = in_process(args.n) + through_router(args.n)
    print(table(["path", "p50 µs", "p99 µs", "max µs", "target", "verdict"], rows))
    for path, target, base in (("in-process", 1e-3, rows[4]), ("router", 5e-3, rows[6])):
        if float(base[2]) * 1e-6 > target:
            print(f"note: raw Zenoh alone ({base[0].split(': ')[1]}) has p99 {base[2]} µs in this run, over the "
                  f"{path} target: the tail is the machine's load, not the check")
    return 0 if all(r[-1] != "MISS" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
