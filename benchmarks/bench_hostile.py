"""Hostile requests against an embedded ``skinet run`` (issues 14 and 25; docs/semantics.md §6, §7).

Monitor and predictor share one peer session, as in ``skinet run``.  An attacker on
the same session serves the consistent 1.9 KB bundle of
``tests/services/hostile.py`` (ten resources, ten skills, 2^10 DNF clauses per
guard, seconds to build) and asks for predictions of it with ``budget=0.1``, again and again, while
events of the paper's mission are sent to the monitor one at a time, every 5 ms,
and the latency event -> Verdicts is measured.  Phases, in one run:

- *quiet*: no attack (the baseline);
- *bad requests* (issue 25, item 6): another process, a client of the run's
  session, sends oversized (1 MiB) and ill-typed requests to the predictor
  (``predict``) and to the monitor's command check (``check``), ``--rate`` per
  second in turn, each under one of 64 client names (no access control: the
  per-client rate limits do not stop it), and times each refusal;
- *isolated*: the attack against our predictor (worker processes with a memory
  limit, killed at budget + grace);
- *in-process peer*: what building the same model does to the monitor when it
  runs on a thread of the monitor's process, as the predictor did before;
- *rotating names* (issue 31, item 4): another process asks the command check from
  ``--flood-threads`` threads as fast as it can, each request under a new client name
  (``check/bad{i}``), while a well-behaved client asks under its own name 10 times a
  second; its check latency is compared with the same client's in a quiet phase;
- *wait slots* (issue 31, item 4): on a second monitor that cannot vouch for its state
  (no bridge), another process keeps its 256 waiting slots full (requests with
  ``wait: 30`` under 10 names, 40 a second, within every rate limit), while the
  well-behaved client asks with ``wait: 1`` twice a second: is its wait honoured?

Printed: verdict p50/p99/max per phase, the predictor's peak memory (its process,
which here also holds the monitor, and its largest worker) against the limit, and
how many hostile requests were answered and how fast; per kind of bad request, how
many were refused, how fast, and the first error.  Targets: p99 under the hostile
model <= max(2 x quiet p99, 5 ms); under bad requests <= 2 x quiet p99; every bad
request refused, p99 <= 0.1 s; worker peak <= the limit; every hostile request
answered within budget + grace + 1 s (plus a replacement's start-up); under the
rotating names, the good client's check p90 <= 2 x quiet and every one of its requests
answered, and the flood's answers within the new names' budget; under the wait-slot
flood, every wait of the good client honoured.  Whatever the
tree's check does with an oversized request (a size limit, a decoding error, an
unknown name with suggestions), it is timed and its reply shown.

    python benchmarks/bench_hostile.py [--seconds 10] [--memory-mb 512] [--rate 40] [--flood-threads 4]
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import resource
import statistics
import threading
import time
from pathlib import Path

from common import ROOT, table, verdict

import msgpack  # noqa: E402
import zenoh  # noqa: E402

from bench_latency import Arrivals, events, ping_pong  # noqa: E402
from services.common.ratelimit import CHECK_RATE_LIMIT  # noqa: E402
from services.common.zenoh_config import session_config  # noqa: E402
from services.monitor.check import parse_command  # noqa: E402
from services.monitor import start_monitor  # noqa: E402
from services.predictor import start_predictor  # noqa: E402
from skinet.system.load import load_system
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import DecodeError, decode, encode  # noqa: E402
from skinet.wire.convert import bundle, statuses, system_from_bundle  # noqa: E402
from skinet.wire.messages import CheckReply, PredictReply, PredictRequest  # noqa: E402
from tests.bridge_side import BridgeSide  # noqa: E402
from tests.loopback import free_endpoint  # noqa: E402
from tests.services.hostile import Attacker, hostile_bundle  # noqa: E402

GRACE = 1.0
BIG = 1 << 20  # bytes of an oversized request


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
                base = arrivals.count
                try:
                    out += ping_pong(lambda i: session.put(*self.payloads[self.next], express=True), arrivals, 1, 0)
                except TimeoutError:  # a stalled monitor: counted at the wait's bound, its late verdict awaited
                    out.append(5.0)
                    while arrivals.count <= base and time.monotonic() < end + 60:
                        time.sleep(0.01)
                self.next += 1
                time.sleep(gap)
            return out
        finally:
            arrivals.close()


def bad_requests() -> list[tuple[str, str, bytes]]:
    """(kind, service, payload) of every bad request the flood sends."""
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    good = PredictRequest(system="spot_arm", digest=bundle(system).digest, seq=1,
                          skillsets=statuses(system, system.initial_marking())).model_dump(mode="json")
    padded = {**good, "skillsets": {**good["skillsets"], "spot": {
        "resources": {f"r{i}": "x" * 1000 for i in range(BIG // 1000)}, "running": []}}}
    return [
        ("predict, 1 MiB marking", "predict", msgpack.packb(padded)),
        ("predict, budget \"1.0\" (a string)", "predict", msgpack.packb({**good, "budget": "1.0"})),
        ("predict, seq 1.5", "predict", msgpack.packb({**good, "seq": 1.5})),
        ("check, 1 MiB transition name", "check", msgpack.packb({"v": 1, "skillset": "spot", "transition": "x" * BIG})),
        ("check, skillset 7, transition a list", "check",
         msgpack.packb({"v": 1, "skillset": 7, "transition": ["go_to_waypoint.start"]})),
    ]


def flood(endpoint: str, service: str, seconds: float, rate: float, out: "multiprocessing.Queue[dict]") -> None:
    """In another process: every bad request to ``service`` in turn, ``rate`` per second, each one timed."""
    session = zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))
    kinds = [k for k in bad_requests() if k[1] == service]
    result: dict[str, dict] = {k: {"times": [], "refused": 0, "answered": 0, "silent": 0, "error": ""}
                               for k, _, _ in kinds}
    start, n = time.monotonic(), 0
    try:
        while time.monotonic() < start + seconds:
            kind, _, payload = kinds[n % len(kinds)]
            client = f"attacker{n % 64}"
            key = keys.predict("spot_arm", client) if service == "predict" else keys.check("spot_arm", client)
            n += 1
            t0 = time.perf_counter()
            replies = list(session.get(key, payload=payload, timeout=10.0))
            r = result[kind]
            r["times"].append(time.perf_counter() - t0)
            why, ok = "", False
            for reply in replies:
                if reply.ok is None:
                    why = f"error reply: {reply.err.payload.to_string()}"
                    continue
                try:
                    msg = decode(reply.ok.payload.to_bytes(), PredictReply if service == "predict" else CheckReply)
                except DecodeError as exc:
                    why = f"undecodable reply: {exc}"
                    continue
                ok, why = msg.ok, msg.error
            r["answered" if ok else "refused" if replies else "silent"] += 1
            r["error"] = r["error"] or why[:150]
            time.sleep(max(0.0, start + n / rate - time.monotonic()))
    finally:
        session.close()
        out.put(result)


CHECK = parse_command("spot:init_power.start")


def rotating(endpoint: str, seconds: float, threads: int, out: "multiprocessing.Queue[dict]") -> None:
    """In another process: check requests from ``threads`` threads, each under a new client name, for
    ``seconds``; counts the answers by their first words."""
    session = zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))
    payload = encode(CHECK)
    counts: dict[str, int] = {}
    lock = threading.Lock()
    end = time.monotonic() + seconds

    def run(t: int) -> None:
        n = 0
        while time.monotonic() < end:
            n += 1
            what = "no reply"
            for reply in session.get(keys.check("spot_arm", f"bad{t}x{n}"), payload=payload, timeout=10.0):
                msg = decode(reply.ok.payload.to_bytes(), CheckReply) if reply.ok is not None else None
                what = "error reply" if msg is None else "answered" if msg.ok else msg.error.split(":")[0] + (
                    ": new names" if "new clients" in msg.error else ": all clients" if "all clients" in msg.error
                    else ": its own budget")
            with lock:
                counts[what] = counts.get(what, 0) + 1

    workers = [threading.Thread(target=run, args=(t,)) for t in range(threads)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    session.close()
    out.put(counts)


def hog(endpoint: str, system: str, seconds: float, out: "multiprocessing.Queue[dict]") -> None:
    """In another process: requests that ask to wait 30 s, 40 a second under 10 names (within every rate
    limit), for ``seconds``; counts those answered before their wait was over."""
    session = zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))
    payload = encode(CHECK.model_copy(update={"wait": 30.0}))
    early = [0]
    start, n = time.monotonic(), 0

    def count(reply: zenoh.Reply) -> None:
        if time.monotonic() < end - 1.0:
            early[0] += 1

    end = start + seconds
    while time.monotonic() < end:
        session.get(keys.check(system, f"hog{n % 10}"), zenoh.handlers.Callback(count), payload=payload, timeout=60)
        n += 1
        time.sleep(max(0.0, start + n / 40 - time.monotonic()))
    session.close()
    out.put({"sent": n, "answered early": early[0]})


class GoodClient:
    """A well-behaved client of the command check: one request every ``gap`` s under its own name, timed."""

    def __init__(self, session: zenoh.Session, system: str = "spot_arm", gap: float = 0.1, wait: float = 0.0):
        self.session, self.key, self.gap = session, keys.check(system, "good"), gap
        self.payload = encode(CHECK.model_copy(update={"wait": wait}))
        self.times: list[float] = []
        self.outcomes: dict[str, int] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.perf_counter()
            replies = list(self.session.get(self.key, payload=self.payload, timeout=40.0))
            self.times.append(time.perf_counter() - t0)
            msg = decode(replies[0].ok.payload.to_bytes(), CheckReply) if replies and replies[0].ok else None
            what = "no reply" if msg is None else "answered" if msg.ok else msg.error[:60]
            self.outcomes[what] = self.outcomes.get(what, 0) + 1
            self._stop.wait(self.gap)

    def stop(self) -> "GoodClient":
        self._stop.set()
        self._thread.join()
        return self


def row(name: str, xs: list[float]) -> list[object]:
    q = statistics.quantiles(xs, n=100, method="inclusive")
    return [name, f"{statistics.median(xs) * 1e3:.2f}", f"{q[98] * 1e3:.2f}", f"{max(xs) * 1e3:.1f}"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="length of each phase (default: 10)")
    ap.add_argument("--memory-mb", type=int, default=512)
    ap.add_argument("--rate", type=float, default=40.0, help="bad requests per second (default: 40)")
    ap.add_argument("--flood-threads", type=int, default=4,
                    help="threads of the rotating-name flood (default: 4)")
    args = ap.parse_args()

    endpoint = free_endpoint()
    config = session_config("peer", listen=[endpoint], multicast_scouting=False)
    config.insert_json5("scouting/delay", "0")
    session = zenoh.open(config)
    system = load_system(ROOT / "skillsets" / "spot_arm.toml")[0]
    t0 = time.monotonic()
    predictor = start_predictor(session, "bench", memory_mb=args.memory_mb, grace=GRACE)
    startup = time.monotonic() - t0
    monitor = start_monitor(session, system, budget=0.5)
    side = BridgeSide(session, "spot_arm", source="bench", model=system)  # the monitor syncs from it first
    rows = []
    feed = Feed(int(7 * args.seconds / 0.005) + 100)  # the events of every phase
    try:
        quiet = feed.latencies(session, args.seconds)
        rows.append(row("quiet", quiet))

        refusals: dict[str, dict] = {}
        flooded: dict[str, list[float]] = {}
        for service in ("predict", "check"):
            results: multiprocessing.Queue[dict] = multiprocessing.get_context("spawn").Queue()
            flooder = multiprocessing.get_context("spawn").Process(
                target=flood, args=(endpoint, service, args.seconds + 1.5, args.rate, results))
            flooder.start()
            time.sleep(1.5)  # the flooder's session is up and sending
            flooded[service] = feed.latencies(session, args.seconds)
            refusals |= results.get(timeout=120)
            flooder.join(10)
            rows.append(row(f"bad {service} requests (another process, {args.rate:g}/s)", flooded[service]))

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

        spawn = multiprocessing.get_context("spawn")
        good = GoodClient(session)
        checks_quiet = feed.latencies(session, args.seconds)
        good_quiet = good.stop()
        rows.append(row("quiet, with the good check client", checks_quiet))
        results = spawn.Queue()
        flooder = spawn.Process(target=rotating, args=(endpoint, args.seconds + 1.5, args.flood_threads, results))
        rate_limited_before = monitor.check_counters.rate_limited
        flooder.start()
        time.sleep(1.5)  # the flooder's session is up and sending
        good = GoodClient(session)
        checks_rotating = feed.latencies(session, args.seconds)
        good_rotating = good.stop()
        rotated = results.get(timeout=120)
        flooder.join(10)
        rotated_refused = monitor.check_counters.rate_limited - rate_limited_before
        rows.append(row(f"rotating names ({args.flood_threads} threads of check/bad{{i}})", checks_rotating))

        waits = start_monitor(session, dataclasses.replace(system, name="spot_arm_waits"), budget=0.5)
        results = spawn.Queue()
        hogging = spawn.Process(target=hog, args=(endpoint, "spot_arm_waits", args.seconds + 8.0, results))
        hogging.start()
        deadline = time.monotonic() + 30
        while len(waits._waiting) < 256 and time.monotonic() < deadline:  # the slots full: the attack is on
            time.sleep(0.1)
        full_after = len(waits._waiting)
        good = GoodClient(session, "spot_arm_waits", gap=0.5, wait=1.0)
        time.sleep(args.seconds)
        good_waits = good.stop()
        hogged = results.get(timeout=120)
        hogging.join(10)
        made_room = waits.check_counters.made_room
        waits.close()
    finally:
        monitor.close()
        side.close()
        predictor.close()
        session.close()

    print(f"## Hostile requests vs. a co-located monitor ({len(quiet)}, {len(flooded['predict'])}, "
          f"{len(flooded['check'])}, {len(isolated)}, {len(inproc)} events)\n")
    print(table(["phase", "verdict p50 ms", "p99 ms", "max ms"], rows))
    q99 = lambda xs: statistics.quantiles(xs, n=100, method="inclusive")[98]  # noqa: E731
    print(f"\n### Bad requests, refused by the tree as it is (predictor counts: {dict(predictor.counts)})\n")
    kinds = []
    for kind, r in refusals.items():
        times = r["times"] or [float("nan")]
        p99 = q99(times) if len(times) > 1 else times[0]
        quick = r["refused"] == len(r["times"]) and p99 <= 0.1
        kinds.append([kind, len(r["times"]), r["refused"], r["answered"], r["silent"],
                      f"{statistics.median(times) * 1e3:.2f}", f"{p99 * 1e3:.2f}", verdict(quick), r["error"]])
    print(table(["request", "sent", "refused", "answered", "no reply", "p50 ms", "p99 ms",
                 "all refused, p99 <= 100 ms", "first error"], kinds))
    print()
    figures = []
    for service, xs in flooded.items():
        figures += [
            [f"verdict p99 under bad {service} requests", f"{q99(xs) * 1e3:.2f} ms ({q99(xs) / q99(quiet):.2f} x quiet)",
             f"<= {2 * q99(quiet) * 1e3:.2f} ms (2 x quiet)", verdict(q99(xs) <= 2 * q99(quiet))],
            [f"verdict p50 under bad {service} requests", f"{statistics.median(xs) * 1e3:.2f} ms "
             f"({statistics.median(xs) / statistics.median(quiet):.2f} x quiet)", "-", ""]]
    print(table(["figure", "value", "target", ""], figures))
    target = max(2 * q99(quiet), 0.005)
    worker_peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    slowest = max(t for t, _ in answers)
    bound = 0.1 + GRACE + 1.0 + 2 * startup
    print()
    print(table(["figure", "value", "target", ""], [
        ["verdict p99 under the hostile model", f"{q99(isolated) * 1e3:.2f} ms", f"<= {target * 1e3:.2f} ms",
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

    p90 = lambda xs: statistics.quantiles(xs, n=10, method="inclusive")[8]  # noqa: E731
    sent = sum(rotated.values())
    new_names = CHECK_RATE_LIMIT + CHECK_RATE_LIMIT * (args.seconds + 1.5)
    honoured = sum(t >= 1.0 for t in good_waits.times)
    print(f"\n### Check limits a client cannot dodge (issue 31): the good client asks check/good\n")
    print(table(["figure", "value", "target", ""], [
        ["good client's check p50, quiet", f"{statistics.median(good_quiet.times) * 1e3:.2f} ms", "-", ""],
        ["good client's check p90, quiet", f"{p90(good_quiet.times) * 1e3:.2f} ms", "-", ""],
        ["good client's check p90, rotating names",
         f"{p90(good_rotating.times) * 1e3:.2f} ms ({p90(good_rotating.times) / p90(good_quiet.times):.2f} x quiet)",
         "<= 2 x quiet", verdict(p90(good_rotating.times) <= 2 * p90(good_quiet.times))],
        ["good client's check p50, rotating names", f"{statistics.median(good_rotating.times) * 1e3:.2f} ms "
         f"({statistics.median(good_rotating.times) / statistics.median(good_quiet.times):.2f} x quiet)", "-", ""],
        ["good client's requests answered, rotating names", f"{good_rotating.outcomes}",
         f"all {len(good_rotating.times)}",
         verdict(good_rotating.outcomes.get("answered", 0) == len(good_rotating.times))],
        ["rotating names: flood's requests", f"{sent} ({sent / (args.seconds + 1.5):.0f}/s): {rotated}", "-", ""],
        ["rotating names: flood answered", str(rotated.get("answered", 0)),
         f"<= {new_names:.0f} (the new names' budget)", verdict(rotated.get("answered", 0) <= new_names)],
        ["rotating names: refused (monitor's count)", str(rotated_refused), "-", ""],
        ["verdict p99, rotating names", f"{q99(checks_rotating) * 1e3:.2f} ms "
         f"({q99(checks_rotating) / q99(checks_quiet):.2f} x quiet with the good client)", "-", ""],
        ["wait slots: waiting when the good client came", f"{full_after}", "256 (full)", verdict(full_after == 256)],
        ["wait slots: hog's requests", f"{hogged['sent']}, {hogged['answered early']} answered before their wait",
         "-", ""],
        ["wait slots: good client's waits honoured (>= 1 s)", f"{honoured}/{len(good_waits.times)}", "all",
         verdict(honoured == len(good_waits.times) > 0)],
        ["wait slots: hog's requests answered early to make room", str(made_room), "-", ""],
    ]))


if __name__ == "__main__":
    main()
