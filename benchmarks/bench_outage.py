"""Outages between the managers and the monitor (issue 30, item 7; docs/performance.md "Outages").

Processes on one loopback router (a session of this script, so that it can be closed and
opened again): the simulated robot (``tests/services/robot_world.py``: the managers'
protocol, status on change only), the bridge and the monitor.  This script watches the
monitor's live state.

Convergence.  Each repetition starts a fresh chain (Spot at PowerOff, idle), starts
``spot:init_power`` (the robot ends it with success 1 s later) and, as soon as the monitor shows
it running, injects a fault: the managers' process frozen 12 s (SIGSTOP, past Zenoh's 10 s lease),
or the router closed 3 s (the skill ends while the link is down: its outcome is never delivered).
Timed: from the link's return (SIGCONT, the router open again) to the first live state where every
skillset is ``live`` and Spot's marking is the managers' (PowerOn, nothing running); p50/p99 over
the repetitions.  Ours: the bridge's anti-entropy polling every 1 s (``--status-poll 1``, the
default).  Baseline, in the same run: polling off (``--status-poll 3600``), where nothing asks a
silent manager again; a repetition that has not converged after ``--give-up`` seconds counts as
not converged.

Cost.  Idle managers for ``--idle`` seconds with the bridge polling every 1 s, then polling off:
CPU seconds of the bridge and of the robot's process (/proc), and messages per second per manager
(status requests the manager answered and statuses it published, over the robot process's whole life).

    python benchmarks/bench_outage.py [--reps 5] [--idle 20] [--give-up 20]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import zenoh  # noqa: E402

from services.common.zenoh_config import session_config  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import decode  # noqa: E402
from skinet.wire.messages import LiveState  # noqa: E402
from tests.loopback import free_port  # noqa: E402

SYSTEM = ROOT / "skillsets" / "spot_arm.toml"
OFF = "3600"  # the longest period the bridge accepts: no poll within a run


class Router:
    def __init__(self) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.session: zenoh.Session | None = None
        self.up()

    def up(self) -> None:
        config = session_config("router", listen=[self.endpoint], multicast_scouting=False)
        config.insert_json5("scouting/delay", "0")
        self.session = zenoh.open(config)

    def down(self) -> None:
        assert self.session is not None
        self.session.close()
        self.session = None


class Chain:
    """The robot, the bridge (polling every ``poll`` s) and the monitor, with the monitor's last live state."""

    def __init__(self, router: Router, poll: str) -> None:
        self.started = time.monotonic()
        self.lifetime = 0.0
        client = ["--mode", "client", "--connect", router.endpoint, "--no-multicast-scouting"]
        self.robot = subprocess.Popen([sys.executable, "-m", "tests.services.robot_world", str(SYSTEM), "--connect",
                                       router.endpoint], cwd=ROOT, stdout=subprocess.PIPE, text=True)
        assert self.robot.stdout is not None and self.robot.stdout.readline() == "ready\n"
        self.bridge = subprocess.Popen([sys.executable, "-m", "services.bridge_ros2", str(SYSTEM), "--status-poll",
                                        poll, *client], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.monitor = subprocess.Popen([sys.executable, "-m", "services.monitor", str(SYSTEM), *client], cwd=ROOT,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.session = zenoh.open(session_config("client", connect=[router.endpoint], multicast_scouting=False))
        self.state: LiveState | None = None
        self._cond = threading.Condition()
        self._sub = self.session.declare_subscriber(keys.state("spot_arm"), self._take)

    def _take(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.state = decode(sample.payload.to_bytes(), LiveState)
            self._cond.notify_all()

    def wait(self, ready: Callable[[LiveState], bool], timeout: float) -> float | None:
        """The monotonic time at which a live state first satisfied ``ready``; None after ``timeout``."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self.state is None or not ready(self.state):
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            return time.monotonic()

    def close(self) -> dict:
        """Stop everything; the robot's counts."""
        self._sub.undeclare()
        self.session.close()
        os.kill(self.robot.pid, signal.SIGCONT)
        for proc in (self.bridge, self.monitor, self.robot):
            proc.send_signal(signal.SIGTERM)
        out, _ = self.robot.communicate(timeout=30)
        self.lifetime = time.monotonic() - self.started
        for proc in (self.bridge, self.monitor):
            proc.wait(30)
        line = next((x for x in out.splitlines() if x.startswith("counts ")), "counts {}")
        return json.loads(line[len("counts "):])


def all_live(s: LiveState) -> bool:
    return bool(s.sync) and all(v.state == "live" for v in s.sync.values())


def initial(s: LiveState) -> bool:
    spot = s.skillsets.get("spot")
    return all_live(s) and spot is not None and spot.resources.get("power_status") == "PowerOff" \
        and not spot.running


def running(s: LiveState) -> bool:
    spot = s.skillsets.get("spot")
    return spot is not None and spot.running == ["init_power"]


def converged(s: LiveState) -> bool:
    spot = s.skillsets.get("spot")
    return all_live(s) and spot is not None and spot.resources.get("power_status") == "PowerOn" and not spot.running


def convergence(poll: str, fault: str, reps: int, give_up: float) -> list[float | None]:
    """One fresh chain per repetition (with polling off, nothing would show a reset manager again)."""
    out: list[float | None] = []
    for _ in range(reps):
        router = Router()
        chain = Chain(router, poll)
        try:
            if chain.wait(initial, 30) is None:
                raise SystemExit(f"bench_outage: the monitor never showed Spot live and idle (poll {poll} s)")
            os.kill(chain.robot.pid, signal.SIGUSR1)
            if chain.wait(running, 30) is None:
                raise SystemExit(f"bench_outage: the monitor never showed init_power running (poll {poll} s)")
            if fault == "frozen":
                os.kill(chain.robot.pid, signal.SIGSTOP)
                time.sleep(12.0)
                os.kill(chain.robot.pid, signal.SIGCONT)
            else:
                router.down()
                time.sleep(3.0)
                router.up()
            back = time.monotonic()
            at = chain.wait(converged, give_up)
            out.append(None if at is None else at - back)
        finally:
            chain.close()
            if router.session is not None:
                router.session.close()
    return out


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cost(poll: str, idle: float) -> dict:
    router = Router()
    chain = Chain(router, poll)
    try:
        if chain.wait(all_live, 30) is None:
            raise SystemExit(f"bench_outage: the monitor never showed every skillset live (poll {poll} s)")
        before = {p: cpu_seconds(p.pid) for p in (chain.bridge, chain.robot)}
        time.sleep(idle)
        after = {p: cpu_seconds(p.pid) for p in (chain.bridge, chain.robot)}
    finally:
        counts = chain.close()
        if router.session is not None:
            router.session.close()
    return {"bridge_cpu": after[chain.bridge] - before[chain.bridge],
            "robot_cpu": after[chain.robot] - before[chain.robot],
            "counts": counts, "seconds": chain.lifetime}


def percentiles(xs: list[float | None]) -> str:
    done = sorted(x for x in xs if x is not None)
    missing = len(xs) - len(done)
    if not done:
        return f"none converged ({missing} of {len(xs)} not within the give-up time)"
    p50 = statistics.median(done)
    p99 = done[min(len(done) - 1, round(0.99 * (len(done) - 1)))]
    return f"p50 {p50 * 1000:7.0f} ms  p99 {p99 * 1000:7.0f} ms" + (f"  ({missing} not converged)" if missing else "")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=5, help="faults of each kind per polling setting (default 5)")
    p.add_argument("--idle", type=float, default=20.0, help="seconds of idle managers per cost run (default 20)")
    p.add_argument("--give-up", type=float, default=20.0, help="seconds after which a repetition has not "
                   "converged (default 20)")
    args = p.parse_args()
    print(f"== convergence after the link's return ({args.reps} faults each; Spot's init_power in flight)")
    for fault, label in (("frozen", "managers frozen 12 s"), ("router", "router closed 3 s")):
        for poll, name in (("1", "ours: poll 1 s"), (OFF, "baseline: polling off")):
            times = convergence(poll, fault, args.reps, args.give_up)
            print(f"   {label:22} {name:22} {percentiles(times)}", flush=True)
    print(f"== cost of the polling (idle managers, {args.idle:g} s)")
    print("   setting                 bridge CPU s  robot CPU s  msgs/s per manager (requests + statuses)")
    for poll, name in (("1", "ours: poll 1 s"), (OFF, "baseline: polling off")):
        c = cost(poll, args.idle)
        rates = ", ".join(f"{k} {(v['status_requests'] + v['statuses']) / c['seconds']:.2f}"
                          for k, v in sorted(c["counts"].items()))
        print(f"   {name:22} {c['bridge_cpu']:12.2f} {c['robot_cpu']:12.2f}  {rates}", flush=True)


if __name__ == "__main__":
    main()
