"""(d) Monitor latency and throughput: event -> published UnsafeReport (docs/semantics.md §1 fast path).

In-process: one peer session carries the events, the monitor and the
measuring subscriber.  Across processes: this process publishes events to a
loopback router, a ``python -m services.monitor`` process (client mode)
answers through the same router, and this process receives the UnsafeReports
(publisher -> router -> monitor -> router -> subscriber).  Each figure sits
beside raw Zenoh measured in the same run and the same topology: put ->
subscriber, an echo (put -> subscriber -> put -> subscriber, the monitor's
shape with no work) and get -> reply.  No predictor runs: the fast path must
not depend on one.  Events cycle through the paper's mission (14 transitions,
each with its observed status, as the bridge sends them).

Targets: in-process p99 <= 1 ms; across processes p99 <= 5 ms and a burst of
events sustained at >= 20 000 events/s with no loss (the UnsafeReport of every
step received, counted by seq).  The monitor process runs twice: with express
publications (default) and with ``--no-express`` (Zenoh batches the three
messages of a step).  The burst row gives the CPU time per event of each
process, which on a small machine is what bounds the rate.

The in-process monitor also runs without and with incident bundles (``--incidents``, ``--rounds`` rounds of
each, 12 by default, in a random order per round) and without and with each Foxglove view (three rounds in a
random order per round): on its session, in a process of its own through Zenoh, and ``skinet run
--foxglove``'s, a process of its own fed through a pipe by the monitor (``--run-foxglove-only``: that one
alone beside the baseline measured twice, the control, ``--rounds`` rounds), target: p99 with them within 10 %
of without; a row with as many rounds as its baseline also gives the median of its per-round ratio to it.
Beside them runs the peer that sorts Foxglove's cost from Zenoh's: a process of its own subscribed to the
monitor's five keys with a callback that does nothing (the cost any remote view puts on the monitor: the
dashboard, ``skinet watch``); the Foxglove process's p99 is also given as a ratio to it.  The deployed shape
follows: a router, the monitor process and ``skinet foxglove`` (or, instead, the peer) as clients, all on
both cores; then the same shape with the dashboard service running, without and with its ``--foxglove``
option (no Zenoh delivery added).  Last, the shape docs/foxglove.md recommends: the robot (router, monitor,
this process) pinned to one core and a ground station (its own router linked to the robot's, a view) pinned
to the other, without and with ``skinet foxglove`` there (alternated six times).  These rows send their
events back to back unless ``--pace MS`` spaces them.

    python benchmarks/bench_latency.py [--events 2000] [--burst 20000] [--profile]
        [--views-only | --incidents-only | --run-foxglove-only | --dashboard-only] [--rounds N] [--pace MS]
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import pstats
import os
import random
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from common import table, verdict

import msgpack  # noqa: E402
import zenoh  # noqa: E402

from services.common.options import count  # noqa: E402
from services.common.zenoh_config import session_config  # noqa: E402
from services.monitor import start_monitor  # noqa: E402
from tests.bridge_side import BridgeSide  # noqa: E402
from tests.loopback import client_args, free_port  # noqa: E402
from tests.processes import start, start_module, start_skinet, stop_all  # noqa: E402
from skinet.system.load import load_system
from skinet.system.live import LiveSystem  # noqa: E402
from skinet.system.model import marking_to_json  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import encode  # noqa: E402
from skinet.wire.messages import CanonicalEvent, SkillsetStatus  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SYSTEM_FILE = ROOT / "skillsets" / "spot_arm.toml"
MISSION = [
    ("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
    ("spot", "stand_up.success.standing"), ("manipulator", "arm_ready.start"), ("manipulator", "arm_ready.success.ready"),
    ("spot", "teleop.start"), ("spot", "teleop.success.done"), ("manipulator", "arm_RD_to_HP.start"),
    ("manipulator", "arm_RD_to_HP.success.at_home"), ("spot", "sit_down.start"), ("spot", "sit_down.success.sitting"),
    ("spot", "safe_poweroff.start"), ("spot", "safe_poweroff.success.powered_off"),
]
BLOCK = dict(congestion_control=zenoh.CongestionControl.BLOCK, express=True)
FAST = dict(indirect=False)  # measuring callbacks run on Zenoh's thread: the instrument adds no hop


def events(n: int) -> list[tuple[str, bytes]]:
    """``n`` encoded CanonicalEvents cycling through the mission, with observed statuses."""
    system = load_system(SYSTEM_FILE)[0]
    live = LiveSystem(system)
    seq = {"spot": 0, "manipulator": 0}  # #0 is the initial status the monitor syncs from (BridgeSide)
    out = []
    for i in range(n):
        skillset, transition = MISSION[i % len(MISSION)]
        assert live.apply(skillset, transition).divergence is None
        seq[skillset] += 1
        status = SkillsetStatus(**marking_to_json(system, live.marking)[skillset])
        ev = CanonicalEvent(system="spot_arm", skillset=skillset, seq=seq[skillset], stamp=time.time(),
                            source="bench", transition=transition, status=status)
        out.append((keys.events("spot_arm", skillset), encode(ev)))
    return out


class Arrivals:
    """Counts samples on a key and wakes a waiter at the ``n``-th one (keeps payloads if asked)."""

    def __init__(self, session: zenoh.Session, key: str):
        self.count = 0
        self.last = 0.0
        self.kept: list[zenoh.ZBytes] | None = None
        self._target = -1
        self._event = threading.Event()
        self._sub = session.declare_subscriber(key, zenoh.handlers.Callback(self._on, **FAST))

    def _on(self, sample: zenoh.Sample) -> None:
        self.count += 1
        self.last = time.perf_counter()
        if self.kept is not None:
            self.kept.append(sample.payload)
        if self.count >= self._target:
            self._event.set()

    def expect(self, n: int) -> None:
        self._event.clear()
        self._target = n

    def wait(self, timeout: float = 5.0) -> float:
        if not self._event.wait(timeout):
            raise TimeoutError(f"{self._target - self.count} samples missing")
        return self.last

    def close(self) -> None:
        self._sub.undeclare()


def ping_pong(send: Callable[[int], None], arrivals: Arrivals, n: int, warmup: int = 200,
              pace: float = 0.0) -> list[float]:
    """Latency of ``n`` sends, one at a time, each waiting for its arrival, then ``pace`` s (untimed)."""
    out = []
    base = arrivals.count
    for i in range(warmup + n):
        if pace:
            time.sleep(pace)
        arrivals.expect(base + i + 1)
        t0 = time.perf_counter()
        send(i)
        t1 = arrivals.wait()
        if i >= warmup:
            out.append(t1 - t0)
    return out


def get_reply(session: zenoh.Session, key: str, n: int, warmup: int = 200) -> list[float]:
    out = []
    for i in range(warmup + n):
        t0 = time.perf_counter()
        replies = [r for r in session.get(key, payload=b"x", express=True) if r.ok is not None]
        if not replies:
            raise RuntimeError("no reply")
        if i >= warmup:
            out.append(time.perf_counter() - t0)
    return out


def p99(samples: list[float]) -> float:
    return statistics.quantiles(samples, n=100, method="inclusive")[98]


def spread(rounds: list[list[float]]) -> str:
    """The p99 of each round, lowest to highest (µs): how far one configuration's p99 moves between rounds of
    the same run, the noise a 10 % target is read against."""
    each = sorted(p99(r) * 1e6 for r in rounds)
    return f"rounds' p99 {each[0]:.0f}-{each[-1]:.0f}"


def stats(samples: list[float]) -> tuple[str, str, str]:
    return f"{statistics.median(samples) * 1e6:.0f}", f"{p99(samples) * 1e6:.0f}", f"{max(samples) * 1e6:.0f}"


def pooled(rounds: list[list[float]]) -> list[float]:
    return [x for r in rounds for x in r]


def rounds_row(where: str, label: str, rounds: list[list[float]], base: list[list[float]] | None = None,
               target: str = "") -> list[object]:
    """A row of ``rounds`` pooled, the spread of their p99 in its label; with ``base`` (the baseline's rounds),
    the target p99 within 10 % of the baseline's and its verdict."""
    samples = pooled(rounds)
    if base is None:
        return [where, f"{label} ({spread(rounds)})", *stats(samples), target, ""]
    limit = 1.1 * p99(pooled(base))
    return [where, f"{label} ({spread(rounds)}{paired(rounds, base)})", *stats(samples), f"p99 <= {limit * 1e6:.0f}",
            verdict(p99(samples) <= limit)]


def paired(rounds: list[list[float]], base: list[list[float]]) -> str:
    """The median over rounds of a round's p99 over the baseline's in the same round (each round runs every
    configuration once, close in time): what the machine's moods between rounds do not move ('' unless the
    rounds pair up)."""
    if len(rounds) != len(base) or len(rounds) < 2:
        return ""
    ratio = statistics.median(p99(r) / p99(b) for r, b in zip(rounds, base))
    return f"; per round / the baseline's: median {ratio:.2f}"


def echo_entities(session: zenoh.Session) -> list:
    """Raw Zenoh baseline: ping -> pong, and a queryable, with no work."""
    pong = session.declare_publisher("bench/pong", **BLOCK)
    return [
        pong,
        session.declare_subscriber("bench/ping", zenoh.handlers.Callback(lambda s: pong.put(s.payload))),
        session.declare_queryable("bench/query", lambda q: (q.reply("bench/query", b"y"), q.drop())),
    ]


# -- in-process ------------------------------------------------------------------------


def in_process(n: int, profile: bool) -> list[list[object]]:
    system = load_system(SYSTEM_FILE)[0]
    session = zenoh.open(session_config("peer", multicast_scouting=False))
    rows = []
    try:
        one_way = session.declare_publisher("bench/direct", **BLOCK)
        direct = Arrivals(session, "bench/direct")
        rows.append(["in-process", "Zenoh put -> subscriber", *stats(ping_pong(lambda i: one_way.put(b"x"), direct, n)),
                     "", ""])
        direct.close()
        keep = echo_entities(session)
        ping = session.declare_publisher("bench/ping", **BLOCK)
        pong = Arrivals(session, "bench/pong")
        rows.append(["in-process", "Zenoh echo (put -> sub -> put -> sub)",
                     *stats(ping_pong(lambda i: ping.put(b"x"), pong, n)), "", ""])
        rows.append(["in-process", "Zenoh get -> reply", *stats(get_reply(session, "bench/query", n)), "", ""])
        pong.close()
        for indirect in (True, False):
            monitor = start_monitor(session, system, indirect=indirect)
            side = BridgeSide(session, "spot_arm", source="bench", model=system)  # the monitor syncs first
            payloads = events(n + 200)
            publishers = {k: session.declare_publisher(k, **BLOCK) for k in {k for k, _ in payloads}}
            reports = Arrivals(session, keys.unsafe("spot_arm"))
            profiler = cProfile.Profile() if profile and not indirect else None  # runs in this thread then
            if profiler:
                profiler.enable()
            lat = ping_pong(lambda i: publishers[payloads[i][0]].put(payloads[i][1]), reports, n)
            if profiler:
                profiler.disable()
            c = monitor.counters
            assert c.applied == n + 200 and c.lost == c.divergences == c.errors == 0, c
            where = "event callback in a thread of its own" if indirect else "direct event callback"
            rows.append(["in-process", f"monitor: event -> UnsafeReport ({where})", *stats(lat), "p99 <= 1000",
                         verdict(p99(lat) <= 1e-3)])
            reports.close()
            monitor.close()
            side.close()
            for p in publishers.values():
                p.undeclare()
            if profiler:
                print("\nprofile of the in-process run, event callback on the publishing thread (tottime):")
                pstats.Stats(profiler).sort_stats("tottime").print_stats(25)
        del keep
    finally:
        session.close()
    return rows


def one_round(session: zenoh.Session, n: int, pace: float) -> list[float]:
    """``n`` events' latencies (after 200 warm-up) to the UnsafeReport of the monitor on ``session``, one at a time,
    ``pace`` s apart: the events' publishers and the reports' subscriber are declared for the round only."""
    payloads = events(n + 200)
    publishers = {k: session.declare_publisher(k, **BLOCK) for k in {k for k, _ in payloads}}
    reports = Arrivals(session, keys.unsafe("spot_arm"))
    try:
        return ping_pong(lambda i: publishers[payloads[i][0]].put(payloads[i][1]), reports, n, pace=pace)
    finally:
        reports.close()
        for p in publishers.values():
            p.undeclare()


def with_incidents(n: int, rounds: int = 12, pace: float = 0.0) -> list[list[object]]:
    """The in-process monitor's event -> UnsafeReport latency without and with ``--incidents`` (the ring the
    monitor hands its messages to), ``rounds`` rounds of each in a random order per round (a fixed order gave
    the second a few µs at p50 either way); target: p99 with it within 10 % of without."""
    import tempfile

    from services.monitor.incidents import Incidents
    from skinet.wire.convert import bundle

    system = load_system(SYSTEM_FILE)[0]
    session = zenoh.open(session_config("peer", listen=[f"tcp/127.0.0.1:{free_port()}"], multicast_scouting=False))
    modes = ("no --incidents", "with --incidents")
    per_round: dict[str, list[list[float]]] = {m: [] for m in modes}
    try:
        for _ in range(rounds):
            for mode in random.sample(modes, len(modes)):
                folder = tempfile.TemporaryDirectory()
                incidents = Incidents(session, bundle(system), Path(folder.name)) if mode == modes[1] else None
                monitor = start_monitor(session, system, tap=None if incidents is None else incidents.record)
                side = BridgeSide(session, "spot_arm", source="bench", model=system)
                per_round[mode].append(one_round(session, n, pace))
                monitor.close()
                if incidents is not None:
                    incidents.close()
                folder.cleanup()
                side.close()
    finally:
        session.close()
    return [rounds_row("in-process", f"monitor: event -> UnsafeReport, {modes[0]}", per_round[modes[0]],
                       target="baseline"),
            rounds_row("in-process", f"  {modes[1]}", per_round[modes[1]], per_round[modes[0]])]


def with_views(n: int, rounds: int = 3, pace: float = 0.0, modes: tuple[str, ...] | None = None) -> list[list[object]]:
    """The in-process monitor's event -> UnsafeReport latency without and with each view of ``modes`` (default
    :data:`MODES`; the first is the baseline), ``rounds`` rounds of each in a random order per round, so that a
    busy machine loads them alike; target: p99 with a view within 10 % of p99 without.  The Foxglove client is
    a process of its own, as Foxglove is (in the monitor's process its JSON decoding would hold the monitor's
    interpreter)."""

    from services.dashboard.observer import Observer
    from services.foxglove.feed import PipeFeed
    from services.foxglove.server import FoxgloveView

    modes = MODES if modes is None else modes
    system = load_system(SYSTEM_FILE)[0]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(session_config("peer", listen=[endpoint], multicast_scouting=False))
    peer = ("--mode", "peer", "-e", endpoint, "--no-multicast-scouting", "--wait", "0")  # a view's Zenoh flags
    per_round: dict[str, list[list[float]]] = {m: [] for m in modes}
    try:
        for _ in range(rounds):
            for views in random.sample(modes, len(modes)):
                feed = None
                if "skinet run" in views:  # the monitor's tap writes to the view's pipe
                    read, write = os.pipe()
                    feed = PipeFeed("spot_arm", write)
                monitor = start_monitor(session, system, tap=None if feed is None else feed.record)
                side = BridgeSide(session, "spot_arm", source="bench", model=system)
                view = proc = client = None
                if "bare" in views:
                    proc = start([sys.executable, __file__, "--bare-subscriber", endpoint])
                    wait_token(session, keys.alive("spot_arm", "bench-bare", "*"))
                    time.sleep(1.0)  # its subscriptions reach this session, as the Foxglove process's do
                elif feed is not None:
                    proc, client = foxglove_processes("--feed", str(read), *peer, pass_fds=(read,))
                    os.close(read)
                    time.sleep(1.0)  # the view's start-up queries answered before measuring
                elif "another process" in views:
                    proc, client = foxglove_processes(*peer)
                    time.sleep(1.0)  # the view's start-up queries answered before measuring
                elif "Foxglove" in views:
                    observer = Observer(session, "spot_arm", system)
                    view = FoxgloveView(observer, "127.0.0.1", 0)
                    client = fox_client(view.url)
                    time.sleep(1.0)  # the view's start-up queries answered before measuring
                per_round[views].append(one_round(session, n, pace))
                if feed is not None and feed.dropped:
                    print(f"  ({views}: {feed.dropped} messages dropped in {feed.gaps} gaps)", file=sys.stderr)
                if proc is not None:
                    stop_all([p for p in (client, proc) if p is not None])
                if view is not None:
                    stop_all([client])
                    view.close()
                    observer.close()
                monitor.close()
                if feed is not None:
                    feed.close()
                side.close()
    finally:
        session.close()
    rows = [rounds_row("in-process", f"monitor: event -> UnsafeReport, {modes[0]}", per_round[modes[0]],
                       target="baseline"),
            *[rounds_row("in-process", f"  {m}", per_round[m], per_round[modes[0]]) for m in modes[1:]]]
    if MODES[1] in modes and MODES[2] in modes:
        bare, fox = p99(pooled(per_round[MODES[1]])), p99(pooled(per_round[MODES[2]]))
        rows.append(["in-process", "  skinet foxglove's p99 / the bare remote subscriber's", "", f"{fox / bare:.2f}",
                     "", "(peer)", ""])
    return rows


MODES = ("no view", "with a bare remote subscriber of the monitor's keys (peer: any view's Zenoh cost)",
         "with skinet foxglove in another process (1 client)",
         "with the Foxglove view in process (1 client)",
         "with skinet run --foxglove's view (its own process, fed through a pipe; 1 client)")
CONTROL = "no view, again (the control: how far the baseline moves from itself in the same run)"
RUN_FOXGLOVE = (MODES[0], CONTROL, MODES[4])


MONITOR_KEYS = (keys.state, keys.verdicts, keys.unsafe, keys.state_space, keys.divergences)  # what it publishes


def foxglove_processes(*args: str, pass_fds: tuple[int, ...] = ()) -> list[subprocess.Popen]:
    """``skinet foxglove`` (with ``args``, inheriting ``pass_fds``) on a free port, and a Foxglove client process
    subscribed to every channel (:func:`fox_client`)."""
    port = free_port()
    view = start_module("services.foxglove", str(SYSTEM_FILE), "--port", str(port), *args, pass_fds=pass_fds)
    return [view, fox_client(f"ws://127.0.0.1:{port}")]


def fox_client(url: str, prefix: tuple[str, ...] = ()) -> subprocess.Popen:
    """A Foxglove client process (a process apart, as Foxglove is; ``prefix``: a command it runs under, e.g.
    ``taskset``) of the view at ``url``, once it subscribed to every channel: a view's start-up (imports, compiled
    anew under PYTHONDONTWRITEBYTECODE) is not measured."""
    client = start([*prefix, sys.executable, __file__, "--fox-client", url])
    wait_line(client, "subscribed", "the Foxglove client")
    return client


def wait_line(proc: subprocess.Popen, text: str, what: str) -> None:
    """Read the output of ``proc`` (started without a log) up to a line with ``text`` (the lines before it are
    shown); an error if its output ends first."""
    assert proc.stdout is not None
    for line in proc.stdout:
        if text in line:
            return
        print(line, end="", file=sys.stderr)
    raise RuntimeError(f"{what} ended ({proc.wait()}) before saying '{text}'")


def bare_subscriber(endpoint: str, mode: str = "peer") -> None:
    """A process subscribed to the monitor's keys that does nothing with what it gets, until terminated; a
    ``mode`` session (a client of a router, as a deployment's views are; a peer of ``skinet run``'s session)."""
    session = zenoh.open(session_config(mode, connect=[endpoint], multicast_scouting=False))
    subs = [session.declare_subscriber(key("spot_arm"), lambda _sample: None) for key in MONITOR_KEYS]
    token = session.liveliness().declare_token(keys.alive("spot_arm", "bench-bare", "1"))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    stop.wait()
    token.undeclare()
    del subs
    session.close()


async def _fox_client(url: str, aiohttp, json_) -> None:
    """A Foxglove client subscribed to every channel, reading every message until the server closes (or the
    process is terminated); it tries to connect until the server listens."""
    async with aiohttp.ClientSession() as http:
        while True:
            try:
                ws = await http.ws_connect(url, protocols=("foxglove.sdk.v1",))
                break
            except aiohttp.ClientError:
                await asyncio.sleep(0.1)
        async with ws:
            while True:
                msg = await ws.receive()
                if msg.type == aiohttp.WSMsgType.TEXT:
                    op = json_.loads(msg.data)
                    if op["op"] == "advertise":
                        await ws.send_str(json_.dumps({"op": "subscribe", "subscriptions": [
                            {"id": c["id"], "channelId": c["id"]} for c in op["channels"]]}))
                        print("subscribed", flush=True)  # to fox_client(): the view is serving, the client is in
                elif msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                    return


def alternated(a: zenoh.Session, n: int, rounds: int, modes: tuple[str, ...],
               start_views: Callable[[int], list[subprocess.Popen]], settle: float,
               pace: float = 0.0) -> dict[str, list[list[float]]]:
    """Event -> UnsafeReport latencies through a monitor process already synced on ``a``, each of ``modes`` once
    per round in a random order, for ``rounds`` rounds: ``start_views(j)`` starts the processes of mode ``j``
    (given 3 s to subscribe and ask, stopped after its ``n`` events, then ``settle`` s).  ``a`` subscribes to the
    monitor's five keys, as a deployment's pilot and views do; one monitor for all, its seqs going on."""
    views = [a.declare_subscriber(key("spot_arm"), lambda _sample: None)
             for key in MONITOR_KEYS if key is not keys.unsafe]
    reports = Arrivals(a, keys.unsafe("spot_arm"))  # the fifth
    payloads = events((n + 200) * rounds * len(modes))
    publishers = {k: a.declare_publisher(k, **BLOCK) for k in {k for k, _ in payloads}}
    per_round: dict[str, list[list[float]]] = {m: [] for m in modes}
    time.sleep(0.5)
    runs = 0
    for _ in range(rounds):
        for j in random.sample(range(len(modes)), len(modes)):  # no mode always after another
            mode = modes[j]
            run = payloads[runs * (n + 200):]  # the events go on where the last run stopped, whatever the mode
            runs += 1
            procs = start_views(j)
            if procs:
                time.sleep(3.0)  # their subscriptions reached the routers, the view's start-up queries answered
            per_round[mode].append(ping_pong(lambda i: publishers[run[i][0]].put(run[i][1]), reports, n, pace=pace))
            stop_all(procs)
            time.sleep(settle)
    reports.close()
    del views
    return per_round


def through_router(n: int, rounds: int, modes: tuple[str, ...],
                   start_views: Callable[[int, str], list[subprocess.Popen]], settle: float,
                   pace: float) -> list[list[object]]:
    """The deployed shape (compose.yaml) on both cores: a loopback router, the monitor process and this process
    as clients; :func:`alternated` over ``modes`` there (``start_views(j, endpoint)``: mode ``j``'s processes,
    ``endpoint`` the router's); the baseline row (the first mode's) and one row for each of the others."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = start_skinet("router", "--listen", endpoint, "--no-auth")  # loopback only
    procs = [router]
    try:
        listening(router)
        a = zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))
        try:
            side = BridgeSide(a, "spot_arm", source="bench", model=load_system(SYSTEM_FILE)[0])
            procs.append(start_module("services.monitor", str(SYSTEM_FILE), *client_args(endpoint), "--id", "bench",
                                      "--log-level", "WARNING"))
            wait_token(a, keys.alive("spot_arm", "monitor", "bench"))
            side.synced()
            per_round = alternated(a, n, rounds, modes, lambda j: start_views(j, endpoint), settle, pace)
            side.close()
        finally:
            a.close()
    finally:
        stop_all(procs)
    return [rounds_row("router", f"monitor process: event -> UnsafeReport, {modes[0]}", per_round[modes[0]],
                       target="baseline"),
            *[rounds_row("router", f"  {m}", per_round[m], per_round[modes[0]]) for m in modes[1:]]]


def views_through_router(n: int, rounds: int = 3, pace: float = 0.0, control: bool = False) -> list[list[object]]:
    """The deployed shape (:func:`through_router`): this process sends the events and subscribes to the
    monitor's five keys (the pilot and the views a deployment runs), and measures event -> UnsafeReport without
    and with ``skinet foxglove`` connected to the router like any view (one Foxglove client process subscribed
    to every channel; it takes the monitor's feed, one message a round), and with a process subscribed to the
    monitor's five keys through the router that does nothing instead (what a view of every message, such as the
    dashboard, costs there), alternated ``rounds`` times (``control``: the baseline twice); target: p99 with
    Foxglove within 10 % of without."""
    modes = ("no Foxglove", "with skinet foxglove (1 client; the monitor's feed)",
             "with a bare subscriber of the monitor's five keys (a view of every message)",
             *((CONTROL,) if control else ()))

    def views(j: int, endpoint: str) -> list[subprocess.Popen]:
        if j == 1:
            return foxglove_processes(*client_args(endpoint), "--wait", "5")
        return [start([sys.executable, __file__, "--bare-subscriber", endpoint, "--bare-mode", "client"])] \
            if j == 2 else []

    return through_router(n, rounds, modes, views, 0.0, pace)


def dashboard_with_foxglove(n: int, rounds: int = 6, pace: float = 0.0) -> list[list[object]]:
    """The robot's own cores, served as docs/foxglove.md recommends there: the deployed shape
    (:func:`through_router`) with the dashboard service running (``python -m services.dashboard``, no browser),
    without and with its ``--foxglove`` option (one Foxglove client process subscribed to every channel),
    alternated ``rounds`` times; target: p99 with it within 10 % of without.  The dashboard's observer feeds the
    Foxglove view: no Zenoh delivery is added, only the view's rounds and its client."""
    modes = ("with the dashboard service", "with the dashboard service and its --foxglove (1 client)")

    def dashboard(j: int, endpoint: str) -> list[subprocess.Popen]:
        fox = ["--foxglove", str(free_port())] if j else []
        there = [start_module("services.dashboard", str(SYSTEM_FILE), "--port", str(free_port()), *fox,
                              *client_args(endpoint),
                              "--wait", "5", "--log-level", "WARNING")]
        if j:
            there.append(fox_client(f"ws://127.0.0.1:{fox[1]}"))
        return there

    return through_router(n, rounds, modes, dashboard, 0.5, pace)


def listening(router: subprocess.Popen) -> None:
    """Until ``skinet router`` says it listens (the warnings before it are shown)."""
    wait_line(router, "listening", "the router")


def robot_and_ground(n: int, rounds: int = 6, pace: float = 0.0) -> list[list[object]]:
    """The shape docs/foxglove.md recommends, two machines played by the two cores: the robot (its router, the
    monitor process, and this process sending the events and subscribing to the monitor's five keys) pinned to
    CPU 0, the ground station (a router linked to the robot's, a view there) pinned to CPU 1.  The view already
    on the ground station is the dashboard's Zenoh cost (a process subscribed to the monitor's keys that does
    nothing); the row measured adds ``skinet foxglove`` there (one Foxglove client process subscribed to every
    channel), alternated ``rounds`` times; target: p99 with it within 10 % of without.  The first view of a
    ground station (the robot's router forwarding to another) is measured too, as information: that link is
    paid by any ground station, whatever it runs."""
    mine = os.sched_getaffinity(0)
    if len(mine) < 2:
        return [["robot+ground", "skipped: one CPU here (the robot and the ground station need one each)", "", "",
                 "", "", ""]]
    robot_cpu, ground_cpu = sorted(mine)[:2]
    robot, ground = ["taskset", "-c", str(robot_cpu)], ["taskset", "-c", str(ground_cpu)]
    e1, e2 = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    modes = ("no ground view", "ground station with a view (the dashboard's Zenoh cost)",
             "ground station with the view and skinet foxglove (1 client)")
    os.sched_setaffinity(0, {robot_cpu})
    procs = [start([*robot, sys.executable, "-m", "skinet_cli.main", "router", "--listen", e1, "--no-auth"])]
    try:
        listening(procs[0])
        # The ground's router once it links to the robot's (a warning would come first were the robot's not up).
        procs.append(start([*ground, sys.executable, "-m", "skinet_cli.main", "router", "--listen", e2, "--connect",
                            e1, "--no-auth"]))
        listening(procs[1])
        a = zenoh.open(session_config("client", connect=[e1], multicast_scouting=False))
        try:
            side = BridgeSide(a, "spot_arm", source="bench", model=load_system(SYSTEM_FILE)[0])
            procs.append(start([*robot, sys.executable, "-m", "services.monitor", str(SYSTEM_FILE), *client_args(e1),
                                "--id", "bench", "--log-level", "WARNING"]))
            wait_token(a, keys.alive("spot_arm", "monitor", "bench"))
            side.synced()

            def ground_views(j: int) -> list[subprocess.Popen]:
                there = []
                if j > 0:
                    there.append(start([*ground, sys.executable, __file__, "--bare-subscriber", e2]))
                    wait_token(a, keys.alive("spot_arm", "bench-bare", "*"))
                if j > 1:
                    port = free_port()
                    there += [start([*ground, sys.executable, "-m", "services.foxglove", str(SYSTEM_FILE), "--port",
                                     str(port), *client_args(e2), "--wait", "5"]),
                              fox_client(f"ws://127.0.0.1:{port}", tuple(ground))]
                return there

            per_round = alternated(a, n, rounds, modes, ground_views, 0.5, pace)  # 0.5 s: subscriptions undeclared
            side.close()
        finally:
            a.close()
    finally:
        stop_all(procs)
        os.sched_setaffinity(0, mine)
    return [rounds_row("robot+ground", f"monitor process: event -> UnsafeReport, {modes[0]}", per_round[modes[0]],
                       target="(information)"),
            rounds_row("robot+ground", f"  {modes[1]}", per_round[modes[1]], target="baseline"),
            rounds_row("robot+ground", f"  {modes[2]}", per_round[modes[2]], per_round[modes[1]])]


# -- across processes ------------------------------------------------------------------


def wait_token(session: zenoh.Session, key: str, timeout: float = 10.0) -> None:
    seen = threading.Event()
    sub = session.liveliness().declare_subscriber(key, lambda s: seen.set(), history=True)
    try:
        if not seen.wait(timeout):
            raise TimeoutError(f"no liveliness token on {key}")
    finally:
        sub.undeclare()


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def across_processes(n: int, burst: int) -> list[list[object]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    client = client_args(endpoint)
    router = start_skinet("router", "--listen", endpoint, "--no-auth")  # loopback only
    procs = [router]
    rows = []
    try:
        listening(router)
        procs.append(start([sys.executable, __file__, "--echo", endpoint]))
        a = zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))
        b = zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))
        try:
            wait_token(a, "bench/alive/echo")
            one_way = a.declare_publisher("bench/direct", **BLOCK)
            direct = Arrivals(b, "bench/direct")
            time.sleep(0.2)  # let the router learn b's subscriber (no token to wait on)
            rows.append(["router", "Zenoh put -> subscriber", *stats(ping_pong(lambda i: one_way.put(b"x"), direct, n)),
                         "", ""])
            direct.close()
            ping = a.declare_publisher("bench/ping", **BLOCK)
            pong = Arrivals(a, "bench/pong")
            time.sleep(0.2)
            rows.append(["router", "Zenoh echo (put -> sub -> put -> sub)",
                         *stats(ping_pong(lambda i: ping.put(b"x"), pong, n)), "", ""])
            rows.append(["router", "Zenoh get -> reply", *stats(get_reply(a, "bench/query", n)), "", ""])
            pong.close()
            side = BridgeSide(a, "spot_arm", source="bench", model=load_system(SYSTEM_FILE)[0])
            for flags in ([], ["--no-express"]):
                name = "monitor" + (" " + " ".join(flags) if flags else "")
                monitor = start_module("services.monitor", str(SYSTEM_FILE), *client, "--id", "bench",
                                       "--log-level", "WARNING", *flags)
                procs.append(monitor)
                wait_token(a, keys.alive("spot_arm", "monitor", "bench"))
                side.synced()
                payloads = events(n + 200 + burst)
                publishers = {k: a.declare_publisher(k, **BLOCK) for k in {k for k, _ in payloads}}
                reports = Arrivals(a, keys.unsafe("spot_arm"))
                time.sleep(0.2)
                lat = ping_pong(lambda i: publishers[payloads[i][0]].put(payloads[i][1]), reports, n)
                rows.append(["router", f"{name}: event -> UnsafeReport", *stats(lat), "p99 <= 5000",
                             verdict(p99(lat) <= 5e-3)])
                cpu = {"monitor": monitor.pid, "router": router.pid}
                rows.append(throughput(name, publishers, payloads[n + 200:], reports, n + 200, cpu))
                reports.close()
                for pub in publishers.values():
                    pub.undeclare()
                monitor.send_signal(signal.SIGTERM)
                monitor.wait(5)
                gone = threading.Event()
                watch = a.liveliness().declare_subscriber(keys.alive("spot_arm", "monitor", "bench"),
                                                          lambda s: gone.set(), history=False)
                gone.wait(1.0)  # its token's deletion, so the next monitor's token is not confused with it
                watch.undeclare()
            side.close()
        finally:
            a.close()
            b.close()
    finally:
        stop_all(procs)
    return rows


def throughput(name: str, publishers: dict, payloads: list[tuple[str, bytes]], reports: Arrivals, done: int,
               pids: dict[str, int]) -> list[object]:
    """Publish ``payloads`` as fast as BLOCK allows; rate = events / (last report - first put)."""
    reports.expect(reports.count + len(payloads))
    reports.kept = []
    before = {k: cpu_seconds(pid) for k, pid in pids.items()}
    me = time.process_time()
    t0 = time.perf_counter()
    for key, payload in payloads:
        publishers[key].put(payload)
    t_put = time.perf_counter() - t0
    try:
        t1 = reports.wait(timeout=60)
    except TimeoutError:
        t1 = reports.last
    rate = len(payloads) / (t1 - t0)
    seqs = [msgpack.unpackb(p.to_bytes())["seq"] for p in reports.kept]
    reports.kept = None
    lost = len(set(range(done + 1, done + len(payloads) + 1)) - set(seqs))  # steps 1.. follow the events
    per = {k: (cpu_seconds(pid) - before[k]) / len(payloads) * 1e6 for k, pid in pids.items()}
    per["bench"] = (time.process_time() - me) / len(payloads) * 1e6
    cpu = ", ".join(f"{k} {v:.0f}" for k, v in per.items())
    note = f"{len(payloads)} events in {t1 - t0:.2f} s (publisher done in {t_put:.2f} s), {lost} lost; CPU µs/event: {cpu}"
    return ["router", f"{name}: burst, {note}", f"{rate:,.0f}/s", "", "", ">= 20,000/s, no loss",
            verdict(rate >= 20_000 and lost == 0)]


def echo_process(endpoint: str) -> None:
    """The raw-Zenoh peer of the cross-process baseline (client of the router)."""
    session = zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))
    keep = echo_entities(session)
    token = session.liveliness().declare_token("bench/alive/echo")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    while not stop.wait(0.5):
        pass
    token.undeclare()
    del keep
    session.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--events", type=int, default=2000, help="ping-pong events per latency row")
    parser.add_argument("--burst", type=int, default=20000, help="events of the throughput burst")
    parser.add_argument("--profile", action="store_true", help="cProfile the in-process monitor run")
    parser.add_argument("--views-only", action="store_true",
                        help="only the rows without and with --incidents and the Foxglove view")
    parser.add_argument("--incidents-only", action="store_true",
                        help="only the rows without and with --incidents")
    parser.add_argument("--run-foxglove-only", action="store_true",
                        help="only the rows without and with skinet run --foxglove's view (fed through a pipe)")
    parser.add_argument("--router-only", action="store_true",
                        help="only the rows without and with skinet foxglove on the robot's router, and the control "
                             "(--rounds rounds)")
    parser.add_argument("--dashboard-only", action="store_true",
                        help="only the rows without and with the dashboard service's --foxglove (--rounds rounds)")
    parser.add_argument("--rounds", type=count(1), default=12, metavar="N",
                        help="rounds of each configuration in the --incidents, --run-foxglove-only, --router-only and "
                             "--dashboard-only rows (default 12)")
    parser.add_argument("--pace", type=float, default=0.0, metavar="MS",
                        help="in the rows of --incidents and the views, wait MS milliseconds (untimed) before each event: a robot's "
                             "pace rather than back to back (default 0: the flood)")
    parser.add_argument("--echo", help=argparse.SUPPRESS)
    parser.add_argument("--fox-client", help=argparse.SUPPRESS)
    parser.add_argument("--bare-subscriber", help=argparse.SUPPRESS)
    parser.add_argument("--bare-mode", default="peer", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        return echo_process(args.echo)
    if args.bare_subscriber:
        return bare_subscriber(args.bare_subscriber, args.bare_mode)
    if args.fox_client:  # a Foxglove client process subscribed to every channel, until terminated
        import json

        import aiohttp

        return asyncio.run(_fox_client(args.fox_client, aiohttp, json))
    if args.pace < 0:
        parser.error(f"argument --pace: {args.pace:g} is below 0")
    pace = args.pace / 1000
    only = args.views_only or args.incidents_only or args.run_foxglove_only or args.dashboard_only or args.router_only
    rows = [] if only else in_process(args.events, args.profile)
    if args.router_only:
        rows += views_through_router(args.events, args.rounds, pace, control=True)
    elif args.dashboard_only:
        rows += dashboard_with_foxglove(args.events, args.rounds, pace)
    elif args.run_foxglove_only:
        rows += with_views(args.events, args.rounds, pace, RUN_FOXGLOVE)
    else:
        rows += with_incidents(args.events, args.rounds, pace)
    if not (args.incidents_only or args.run_foxglove_only or args.dashboard_only or args.router_only):
        rows += with_views(args.events, pace=pace)
        rows += views_through_router(args.events, pace=pace)
        rows += dashboard_with_foxglove(args.events, pace=pace)
        rows += robot_and_ground(args.events, pace=pace)
    if not only:
        rows += across_processes(args.events, args.burst)
    paced = f", the rows of --incidents and the views {args.pace:g} ms apart" if args.pace else ""
    print(f"\nlatency over {args.events} events after 200 warm-up (µs), loopback, no predictor{paced}")
    print(table(["where", "path", "p50", "p99", "max", "target", ""], rows))


if __name__ == "__main__":
    main()
