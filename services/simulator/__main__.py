"""``python -m services.simulator SCENARIO.toml``: play a scenario on simulated managers (docs/semantics.md §7), or on the
simulated action servers, lifecycle nodes and topics of a system bound to plain ROS 2 interfaces (docs/semantics.md §9)."""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path


from services.common.cli import add_log_arg, one_line_errors, setup_logging
from services.common.zenoh_config import add_zenoh_args, config_from_args, open_session
from services.simulator.driver import StepRun
from services.simulator.service import Simulator
from services.common.options import ArgumentParser, count, key_prefix, load_live_system, number, seconds
from skinet.system.load import load_bindings, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import check_scenario, parse_scenario
from skinet.ros.keys import KeyStyle


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="python -m services.simulator",
        description="Simulate the skillset managers of a scenario's system on Zenoh (ROS 2 topic keys, CDR) "
                    "and play the scenario's steps as operator requests and skill outcomes. A system whose "
                    "skillsets name bindings gets their action servers, lifecycle nodes and topics instead "
                    "(goals sent and cancelled as a client would, results, transition events, topic samples).",
    )
    parser.add_argument("scenario", help="scenario TOML file (its [scenario] system names the system file)")
    parser.add_argument("--speed", type=number(0, env="SKINET_SPEED"), default=os.environ.get("SKINET_SPEED", "1"),
                        help="time scale: step t is played at t/SPEED seconds; 0 = as fast as possible (default: 1)")
    parser.add_argument("--start-delay", type=seconds(zero=True), default=0.0,
                        help="seconds to wait before the first step (time for a bridge to connect)")
    parser.add_argument("--linger", type=seconds(zero=True), default=1.0,
                        help="seconds to keep serving after the last step (default: 1)")
    parser.add_argument("--rmw-zenoh", action="store_true", help="rmw_zenoh keys and attachments instead of "
                        "zenoh-bridge-ros2dds keys")
    parser.add_argument("--namespace", type=key_prefix("namespace"), default="", help="zenoh-bridge-ros2dds namespace prefix of the keys")
    parser.add_argument("--domain", type=count(0, 232), default=0, help="ROS domain id in rmw_zenoh keys (default: 0)")
    parser.add_argument("--ros-distro", default=os.environ.get("ROS_DISTRO", "jazzy"),
                        help="ROS 2 distribution of rmw_zenoh (default: $ROS_DISTRO or jazzy); on humble the keys "
                             "carry TypeHashNotSupported instead of a RIHS01 type hash")
    parser.add_argument("--dds", action="store_true",
                        help="serve the managers as ROS 2 nodes on DDS domain --domain (CycloneDDS, "
                             "ros_discovery_info of --ros-distro) for a zenoh-bridge-ros2dds to route; the scenario's "
                             "requests still go through Zenoh. Needs the cyclonedds package; $CYCLONEDDS_URI "
                             "configures DDS (default: unicast discovery on 127.0.0.1)")
    add_log_arg(parser)
    add_zenoh_args(parser)
    return parser


def _line(run: StepRun) -> str:
    s = run.step
    what = f"{s.skillset}:{s.transition}" if s.transition else f"(considers {s.skillset}:{s.consider})"
    flag = "" if run.ok else "   (no effect)"
    return f"step {run.index:>3}  t={s.t:>6.1f}s  {run.action:<9} {what}{' ' + run.detail if run.detail else ''}{flag}"


@one_line_errors("python -m services.simulator")
def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.dds and args.rmw_zenoh:
        parser.error("--dds and --rmw-zenoh exclude each other")
    setup_logging(args)
    path = Path(args.scenario)
    scenario = parse_scenario(read_text(path), str(path))
    system_path = path.parent / scenario.system
    system, _ = load_live_system(system_path)
    check_scenario(scenario, system, str(path))
    typemap = load_typemap(system_path)
    bindings, _ = load_bindings(system)
    if bindings and len(bindings) != len(system.components):
        raise ValueError("the simulator plays systems of managers or of bindings, not both in one system yet")
    if bindings and args.dds:
        parser.error("--dds simulates skillset managers only (bound action servers: tests/dds)")
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    session = open_session(config_from_args(args))
    try:
        style = KeyStyle(args.rmw_zenoh, args.namespace, args.domain, args.ros_distro == "humble")
        if args.dds:
            try:
                from services.simulator.dds import DdsSimulator  # optional dependency: cyclonedds
            except ImportError as exc:
                print(f"error: --dds needs the cyclonedds package ({exc})", file=sys.stderr)
                return 2
            sim = DdsSimulator(session, system, typemap, domain=args.domain, distro=args.ros_distro,
                               config=os.environ.get("CYCLONEDDS_URI"), style=style)
        elif bindings:
            from services.simulator.bound import BoundSimulator

            sim = BoundSimulator(session, system, bindings, style=style)
        else:
            sim = Simulator(session, system, typemap, style=style)
        time.sleep(max(0.0, args.start_delay))
        if bindings:  # the robot's first samples, once a bridge had time to connect
            sim.publish_topics(scenario.topics)
        sim.drive(scenario, args.speed, on_step=lambda run: print(_line(run), flush=True))  # errors: one line
        time.sleep(max(0.0, args.linger))
        sim.close()
    except KeyboardInterrupt:
        return 130
    finally:
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
