"""The bridge under two managers publishing in turn at full speed (SPEC §1, §7).

Spot and arm managers of ``skillsets/spot_arm.toml`` (the simulator's
:class:`~services.simulator.manager.Manager`) each play ``--cycles`` skill
executions; their CDR messages are published alternately from one Zenoh
session to a bridge on another, over loopback TCP.  Printed per run: messages
per second from the first publication to the last event, and *inversions*:
events that came out before one the same messages, fed to a
:class:`~services.bridge_ros2.Feed` in publication order, put earlier.

Ours: the bridge as shipped, its subscriptions calling back on Zenoh's own
thread.  Baseline: the same bridge with each subscription's callback in a
Python thread of its own (zenoh-python's default, the bridge before session 7),
which loses the order across managers.  Each run in a fresh process.

    python benchmarks/bench_bridge.py [--cycles 2000] [--runs 2]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CYCLES = {  # (skill, outcome) played over and over; outcome None: an event
    "spot": [("init_power", "powered_on"), ("stand_up", "standing"), ("teleop", "done"), ("power_switchoff", None)],
    "manipulator": [("arm_ready", "ready"), ("arm_joystick", "released"), ("arm_moving_to_RD", "at_ready"),
                    ("arm_RD_to_HP", "at_home")],
}


class _IndirectZenoh:
    """``zenoh`` as the bridge sees it in the baseline: every Callback in a Python thread of its own."""

    def __init__(self, zenoh: Any):
        self._zenoh = zenoh
        real = zenoh.handlers.Callback
        self.handlers = type("handlers", (), {"Callback": staticmethod(lambda f, indirect=True: real(f))})

    def __getattr__(self, name: str) -> Any:
        return getattr(self._zenoh, name)


def one(mode: str, cycles: int) -> dict:
    """One run in this process: messages/s and inversions."""
    import zenoh

    from services.bridge_ros2 import Feed, start_bridge
    from services.bridge_ros2 import service
    from services.common.zenoh_config import session_config
    from services.simulator.manager import Manager
    from skinet.files import load_system, load_typemap
    from skinet.ros.keys import KeyStyle
    from skinet.ros.typestore import encode as cdr
    from skinet.wire import keys
    from skinet.wire.codec import decode
    from skinet.wire.messages import CanonicalEvent

    path = ROOT / "skillsets" / "spot_arm.toml"
    system, typemap = load_system(path)[0], load_typemap(path)
    feed = Feed(system, typemap, "bench")
    streams = []
    for name, cycle in CYCLES.items():
        comp = system.component(name)
        store = feed.managers[name].store
        manager = Manager(comp.skillset, store, info=comp.manager)
        messages = manager.status_request()
        for i in range(cycles):
            skill, outcome = cycle[i % len(cycle)]
            messages += manager.raise_event(skill) if outcome is None else \
                manager.skill_request(skill, str(i)) + manager.terminate(skill, "success", outcome)
        topics = {t.topic: t for t in feed.managers[name].topics}
        streams.append([(name, topics[m.topic], cdr(store, m.typename, m.msg)) for m in messages if m.topic in topics])
    interleaved = [m for pair in zip(*streams) for m in pair]
    expected = {(ev.skillset, ev.seq): i for i, ev in enumerate(
        ev for ss, topic, data in interleaved for ev in feed.feed(ss, topic, data))}

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    listener = zenoh.open(session_config("peer", listen=[endpoint], multicast_scouting=False))
    publisher = zenoh.open(session_config("client", connect=[endpoint]))
    order: list[int] = []
    done = threading.Event()

    def on_event(sample: zenoh.Sample) -> None:
        ev = decode(sample.payload.to_bytes(), CanonicalEvent)
        order.append(expected[ev.skillset, ev.seq])
        if len(order) == len(expected):
            done.set()

    sub = listener.declare_subscriber(keys.events(system.name, "*"), zenoh.handlers.Callback(on_event, indirect=False))
    if mode == "baseline":
        service.zenoh = _IndirectZenoh(zenoh)  # type: ignore[assignment]
    bridge = start_bridge(listener, system, typemap, source="bench", request_status=False)
    pubs = {(ss, t.topic): publisher.declare_publisher(KeyStyle().key(system.component(ss).manager, t),
                                                       congestion_control=zenoh.CongestionControl.BLOCK)
            for ss, t, _ in interleaved}
    time.sleep(0.5)  # subscriptions known to the publisher's session
    t0 = time.perf_counter()
    for ss, topic, data in interleaved:
        pubs[ss, topic.topic].put(data)
    finished = done.wait(120)
    seconds = time.perf_counter() - t0
    bridge.close()
    sub.undeclare()
    inversions = sum(1 for a, b in zip(order, order[1:]) if b < a)
    result = {"messages": len(interleaved), "events": len(order), "expected": len(expected),
              "seconds": seconds, "finished": finished, "inversions": inversions}
    print(json.dumps(result), flush=True)
    os._exit(0)  # sessions with callback threads may hang the interpreter's exit


def fresh(mode: str, cycles: int) -> dict:
    r = subprocess.run([sys.executable, __file__, "--one", mode, "--cycles", str(cycles)],
                       capture_output=True, text=True, timeout=600)
    lines = [line for line in r.stdout.splitlines() if line.startswith("{")]
    if r.returncode != 0 or not lines:
        raise SystemExit(f"bench_bridge: the {mode} run failed:\n{r.stderr[-2000:]}")
    return json.loads(lines[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cycles", type=int, default=2000, help="skill executions per manager (default 2000)")
    p.add_argument("--runs", type=int, default=2, help="runs of each, alternating (default 2)")
    p.add_argument("--one", choices=("ours", "baseline"), help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.cycles < 1 or args.runs < 1:
        p.error("--cycles and --runs must be at least 1")
    if args.one:
        one(args.one, args.cycles)
        return
    from common import table

    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {args.cycles} cycles per manager\n")
    rows = []
    for run in range(args.runs):
        for mode, label in (("ours", "ours: callbacks on Zenoh's thread"),
                            ("baseline", "baseline: a Python thread per subscription")):
            r = fresh(mode, args.cycles)
            rows.append([label, str(run + 1), f"{r['messages']:,}", f"{r['events']:,}/{r['expected']:,}",
                         f"{r['messages'] / r['seconds']:,.0f}", f"{r['inversions']:,}"])
    print(table(["bridge", "run", "messages", "events", "messages/s", "inversions"], rows))


if __name__ == "__main__":
    main()
