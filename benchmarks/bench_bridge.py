"""The bridge under two managers publishing in turn at full speed (docs/semantics.md §1, §7), and on action
statuses of a bound skillset beside manager statuses (docs/semantics.md §9).

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

Then, side by side, one skill played over and over (``--cycles`` executions) by a
skillset manager (its ``SkillsetStatus`` and responses) and by an action server
(``GoalStatusArray`` of a bound skill, the goal id changing every execution):
messages per second through the bridge at full speed, and the latency from a
status message's publication to its canonical event, paced (``--samples`` status
messages, 2 ms apart), p50 and p99.  A third latency row ends goals ABORTED in a
mode named by their result: the bridge asks ``get_result`` before it can name it.

    python benchmarks/bench_bridge.py [--cycles 2000] [--runs 2] [--samples 400]
"""

from __future__ import annotations

import argparse
import json
import os
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


def _sessions() -> tuple[Any, Any]:
    """The bridge's session listening on a free loopback port, and a client of it that publishes."""
    import zenoh

    from services.common.zenoh_config import session_config
    from tests.loopback import free_endpoint

    endpoint = free_endpoint()
    listener = zenoh.open(session_config("peer", listen=[endpoint], multicast_scouting=False))
    return listener, zenoh.open(session_config("client", connect=[endpoint]))


def one(mode: str, cycles: int) -> dict:
    """One run in this process: messages/s and inversions."""
    import zenoh

    from services.bridge_ros2 import Feed, start_bridge
    from services.bridge_ros2 import service
    from services.simulator.manager import Manager
    from skinet.system.load import load_system, load_typemap
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

    listener, publisher = _sessions()
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


BENCH_MODEL = """
skillset bench {
    resource { r { state { Idle Busy } initial Idle transition all } }
    skill work {
        precondition { idle: r == Idle }
        start r -> Busy
        success done { effect r -> Idle }
        failure { failed { effect r -> Idle } slow { effect r -> Idle } }
    }
}
"""
BENCH_ACTION = "bench_msgs/action/Work"
BENCH_BINDING = f"""
[skills.work]
action = "/work"
type = "{BENCH_ACTION}"
success = "done"
failure = "failed"
failure_when = {{ slow = "code == 2" }}
"""


def _action_side(cycles: int, results: bool) -> tuple[Any, Any, list[bytes], Any]:
    """The bound bench system, its binding, the CDR status arrays of ``cycles`` goals and a result server."""
    from skinet.lang.parser import parse_skillset
    from skinet.ros.binding import STATUS_TYPE, parse_binding
    from skinet.ros.typestore import default_instance, encode
    from skinet.system.model import build_system
    from services.simulator.protocols import ABORTED, ActionLogic, SUCCEEDED

    ss = parse_skillset(BENCH_MODEL, "bench.rl")
    system = build_system("bench", [(ss, "", "bench.binding.toml")], "")
    binding = parse_binding(BENCH_BINDING, "bench.binding.toml", ss,
                            {BENCH_ACTION: "int32 x\n---\nint32 code\n---\nint32 done\n"})
    store = binding.store
    logic = ActionLogic(store, BENCH_ACTION)
    arrays = [encode(store, STATUS_TYPE, default_instance(store, STATUS_TYPE))]  # no goal yet: synced
    for i in range(cycles):
        goal = i.to_bytes(16, "little")
        request = encode(store, f"{BENCH_ACTION}_SendGoal_Request", default_instance(
            store, f"{BENCH_ACTION}_SendGoal_Request", goal_id=default_instance(
                store, "unique_identifier_msgs/msg/UUID", uuid=__import__("numpy").frombuffer(goal, "uint8").copy())))
        _, outputs = logic.send_goal(request)
        arrays.append(outputs[0][1])  # ACCEPTED
        ended, _ = logic.finish(ABORTED if results else SUCCEEDED, {"code": 2})
        arrays.append(ended[0][1])
        if len(logic.goals) > 2:  # arrays hold the last goals only, as a server dropping expired ones
            logic.goals.popitem(last=False)
    return system, binding, arrays, logic


def _manager_side(cycles: int) -> tuple[Any, Any, list[tuple[Any, bytes, bool]]]:
    """spot's manager playing teleop ``cycles`` times: (topic, CDR, whether an event follows it)."""
    from services.bridge_ros2 import Feed
    from services.simulator.manager import Manager
    from skinet.system.load import load_system, load_typemap
    from skinet.ros.typestore import encode as cdr

    path = ROOT / "skillsets" / "spot_arm.toml"
    system, typemap = load_system(path)[0], load_typemap(path)
    feed = Feed(system, typemap, "bench")
    comp = system.component("spot")
    store = feed.managers["spot"].store
    manager = Manager(comp.skillset, store, info=comp.manager)
    topics = {t.topic: t for t in feed.managers["spot"].topics}
    messages = manager.status_request() + manager.skill_request("init_power", "p") + \
        manager.terminate("init_power", "success", "powered_on") + manager.skill_request("stand_up", "s") + \
        manager.terminate("stand_up", "success", "standing")
    for i in range(cycles):
        messages += manager.skill_request("teleop", str(i)) + manager.terminate("teleop", "success", "done")
    stream = [(topics[m.topic], cdr(store, m.typename, m.msg), m.topic == manager.status_topic)
              for m in messages if m.topic in topics]
    return system, typemap, stream


def side(kind: str, cycles: int, samples: int) -> dict:
    """Throughput (full speed) and latency (paced) of one kind of status through the bridge, in this process."""
    import zenoh

    from services.bridge_ros2 import start_bridge
    from services.bridge_ros2.bound_live import start_bound_bridge
    from services.simulator.bound import BoundSimulator
    from skinet.ros.keys import KeyStyle
    from skinet.wire import keys

    listener, publisher = _sessions()
    arrived: list[float] = []
    cond = threading.Condition()

    def on_event(_: zenoh.Sample) -> None:
        with cond:
            arrived.append(time.perf_counter())
            cond.notify_all()

    def wait_events(n: int, timeout: float = 60.0) -> bool:
        with cond:
            return cond.wait_for(lambda: len(arrived) >= n, timeout)

    results = kind == "results"
    server = None
    if kind == "manager":
        system, typemap, stream = _manager_side(cycles + samples)
        bridge = start_bridge(listener, system, typemap, source="bench", request_status=False)
        manager = system.component("spot").manager
        pubs = {t.topic: publisher.declare_publisher(KeyStyle().key(manager, t),
                                                     congestion_control=zenoh.CongestionControl.BLOCK)
                for t, _, _ in stream}
        items = [(pubs[t.topic], data, event) for t, data, event in stream]
        head = 9  # initial status and the four statuses before teleop's cycles (spot's init_power, stand_up)
    else:
        system, binding, arrays, logic = _action_side(cycles + samples, results)
        if results:  # a get_result server answering from the goals' results
            server = BoundSimulator(publisher, system, {"bench": binding})
            server.actions[("bench", "work")].logic = logic
        bridge = start_bound_bridge(listener, system, {"bench": binding}, source="bench", hold=5.0)
        key = KeyStyle().name_key("/work/_action/status", "action_msgs/msg/GoalStatusArray")
        status = publisher.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        items = [(status, data, True) for data in arrays]
        head = 1
    sub = listener.declare_subscriber(keys.events(system.name, "*"), zenoh.handlers.Callback(on_event, indirect=False))
    time.sleep(0.5)
    for pub, data, _ in items[:head]:
        pub.put(data)
    wait_events(1 if kind != "manager" else 5)
    pacing, rest = items[head:head + 2 * samples], items[head + 2 * samples:]
    latencies = []
    for pub, data, event in pacing:
        before = len(arrived)
        sent = time.perf_counter()
        pub.put(data)
        if event:
            if not wait_events(before + 1, 10):
                raise SystemExit(f"bench_bridge: no event for a {kind} status")
            latencies.append(arrived[before] - sent)
            time.sleep(0.002)
    expected = len(arrived) + sum(e for _, _, e in rest)
    t0 = time.perf_counter()
    for pub, data, _ in rest:
        pub.put(data)
    finished = wait_events(expected, 120)
    seconds = time.perf_counter() - t0
    bridge.close()
    if server is not None:
        server.close()
    sub.undeclare()
    latencies.sort()
    result = {"messages": len(rest), "seconds": seconds, "finished": finished, "events": len(arrived),
              "p50": latencies[len(latencies) // 2], "p99": latencies[int(len(latencies) * 0.99)]}
    print(json.dumps(result), flush=True)
    os._exit(0)


def fresh(mode: str, cycles: int, samples: int = 400) -> dict:
    r = subprocess.run([sys.executable, __file__, "--one", mode, "--cycles", str(cycles), "--samples", str(samples)],
                       capture_output=True, text=True, timeout=600)
    lines = [line for line in r.stdout.splitlines() if line.startswith("{")]
    if r.returncode != 0 or not lines:
        raise SystemExit(f"bench_bridge: the {mode} run failed:\n{r.stderr[-2000:]}")
    return json.loads(lines[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cycles", type=int, default=2000, help="skill executions per manager (default 2000)")
    p.add_argument("--runs", type=int, default=2, help="runs of each, alternating (default 2)")
    p.add_argument("--samples", type=int, default=400, help="paced status messages timed per kind (default 400)")
    p.add_argument("--one", choices=("ours", "baseline", "manager", "actions", "results"), help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.cycles < 1 or args.runs < 1 or args.samples < 10:
        p.error("--cycles and --runs must be at least 1, --samples at least 10")
    if args.one in ("ours", "baseline"):
        one(args.one, args.cycles)
        return
    if args.one:
        side(args.one, args.cycles, args.samples)
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
    print(f"\nmanager statuses beside action statuses ({args.cycles} executions at full speed, {args.samples} "
          "paced statuses timed)\n")
    rows = []
    for run in range(args.runs):
        for mode, label in (("manager", "manager: SkillsetStatus + responses"),
                            ("actions", "binding: GoalStatusArray"),
                            ("results", "binding: GoalStatusArray, ABORTED mode from get_result")):
            r = fresh(mode, args.cycles, args.samples)
            rows.append([label, str(run + 1), f"{r['messages']:,}", f"{r['messages'] / r['seconds']:,.0f}",
                         f"{r['p50'] * 1e3:.2f} ms", f"{r['p99'] * 1e3:.2f} ms"])
    print(table(["source", "run", "messages", "messages/s", "status -> event p50", "p99"], rows))


if __name__ == "__main__":
    main()
