"""The simulated robot as a process of its own, for the fault matrix (issue 30, item 6).

``python -m tests.services.robot_world SYSTEM --connect ENDPOINT [--rmw-zenoh] [--duration S]``: the
simulated skillset managers (:class:`services.simulator.Simulator`, the managers' real protocol and CDR
bytes, status on change only) on a client session, and :class:`services.simulator.world.World` ending
every skill started ``--duration`` seconds later in its favourable success mode.  Each start it receives
is printed on standard output as ``start SKILLSET:SKILL ID`` at once, so the test that runs it records
every skill the robot was asked to run, across its own restarts.  Runs until SIGTERM, then prints
``counts {...}``: per skillset, the status requests its manager answered and the statuses it published.

For ``benchmarks/bench_outage.py``: SIGUSR1 starts ``spot:init_power`` as an operator would (the world
ends it), SIGUSR2 restarts Spot's manager (back at its initial state, silent until asked).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path

from services.common.zenoh_config import open_session, session_config
from services.simulator import Simulator
from services.simulator.world import World
from skinet.system.load import load_system, load_typemap
from skinet.mission.scenario import parse_scenario
from skinet.pilot.run import Outcomes
from skinet.ros.keys import KeyStyle


POWER_ON = """[scenario]
name = "power_on"
system = "../spot_arm.toml"

[[steps]]
t = 0.0
skillset = "spot"
transition = "init_power.start"
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="robot_world")
    parser.add_argument("system", type=Path)
    parser.add_argument("--connect", required=True)
    parser.add_argument("--rmw-zenoh", action="store_true")
    parser.add_argument("--duration", type=float, default=1.0)
    args = parser.parse_args(argv)
    system = load_system(args.system)[0]
    typemap = load_typemap(args.system)
    style = KeyStyle(rmw_zenoh=True) if args.rmw_zenoh else KeyStyle()
    session = open_session(session_config("client", connect=[args.connect], multicast_scouting=False))
    sim = Simulator(session, system, typemap, style=style)
    sim.on_start.append(lambda skillset, skill, id_: print(f"start {skillset}:{skill} {id_}", flush=True))
    world = World(sim, Outcomes(system, []), args.duration)
    stop, power, reset = threading.Event(), threading.Event(), threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGUSR1, lambda *_: power.set())
    signal.signal(signal.SIGUSR2, lambda *_: reset.set())
    print("ready", flush=True)
    while not stop.wait(0.02):
        if reset.is_set():
            reset.clear()
            sim.restart("spot")
        if power.is_set():
            power.clear()
            sim.drive(parse_scenario(POWER_ON, "power_on.toml"), speed=0)
    counts = {name: {"status_requests": sum(n for topic, n in node.handled.items()
                                            if node.topics[topic].kind == "status_request"),
                     "statuses": sim.statuses_published()[name]} for name, node in sim.nodes.items()}
    print(f"counts {json.dumps(counts)}", flush=True)
    world.close()
    sim.close()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
