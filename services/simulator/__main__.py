"""``python -m services.simulator SCENARIO.toml``: play a scenario on simulated managers (docs/semantics.md §7), or on the
simulated action servers, lifecycle nodes and topics of a system bound to plain ROS 2 interfaces (docs/semantics.md §9).

``python -m services.simulator SYSTEM.toml --self-ending``: the same robot without a scenario, until
stopped; each skill a request starts ends by itself (:mod:`services.simulator.world`), for a pilot or an
operator to drive (docs/pilot.md, *Try the pilot in one command*).  A pilot run file is refused with the
commands that play it.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from pathlib import Path


from services.common.cli import add_log_arg, one_line_errors, setup_logging
from services.common.zenoh_config import add_zenoh_args, config_from_args, open_session
from services.simulator.driver import StepRun
from services.simulator.service import Simulator
from services.simulator.world import simulated_robot
from services.common.cli import stop_on_signals
from services.common.options import (
    ArgumentParser, SelfEndingMisused, add_self_ending_args, count, key_prefix, load_live_system, number, seconds,
    self_ending_options,
)
from skinet.errors import SourceError
from skinet.system.load import load_bindings, load_typemap
from skinet.files.read import read_text
from skinet.files.toml import locate, parse_toml
from skinet.mission.scenario import check_scenario, parse_scenario
from skinet.pilot.run import Outcomes, is_pilot_run, parse_pilot_run
from skinet.ros.keys import KeyStyle


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="python -m services.simulator",
        description="Simulate the skillset managers of a scenario's system on Zenoh (ROS 2 topic keys, CDR) "
                    "and play the scenario's steps as operator requests and skill outcomes. A system whose "
                    "skillsets name bindings gets their action servers, lifecycle nodes and topics instead "
                    "(goals sent and cancelled as a client would, results, transition events, topic samples). "
                    "With --self-ending, a system file's robot without a scenario: each skill a request starts "
                    "(a pilot's, an operator's) ends by itself, until Ctrl-C.",
    )
    parser.add_argument("scenario", metavar="FILE", help="scenario TOML file (its [scenario] system names the system "
                                                         "file), or a system file with --self-ending")
    parser.add_argument("--self-ending", action="store_true",
                        help="FILE is a system file: serve its robot until stopped, each skill ending by itself "
                             "--skill-duration seconds after it starts, in its first success mode or, with "
                             "--failure-rate, in a failure mode (docs/pilot.md); prints each start and end")
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
    add_self_ending_args(parser, "--self-ending")
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
    try:
        duration, rate, seed = self_ending_options(args, "--self-ending", args.self_ending)
    except SelfEndingMisused as exc:
        parser.error(str(exc))
    setup_logging(args)
    path = Path(args.scenario)
    text = read_text(path)
    kind = file_kind(path, text)
    scenario = None
    if args.self_ending and kind != "system":
        parser.error(f"--self-ending takes a system file; {path} is a scenario (its steps end the skills)")
    if kind == "system" and not args.self_ending:
        raise SourceError.at(str(path), locate(text, ("system",)), "a system file, not a scenario: add --self-ending "
                                                                   "to simulate its robot with skills that end by "
                                                                   "themselves")
    if kind == "scenario":
        scenario = parse_scenario(text, str(path))
        path = path.parent / scenario.system
    system, _ = load_live_system(path)
    if scenario is not None:
        check_scenario(scenario, system, str(args.scenario))
    typemap = load_typemap(path)
    bindings, _ = load_bindings(system)
    if bindings and len(bindings) != len(system.components):
        raise ValueError("the simulator plays systems of managers or of bindings, not both in one system yet")
    if bindings and args.dds:
        parser.error("--dds simulates skillset managers only (bound action servers: tests/dds)")
    stop = stop_on_signals() if scenario is None else None
    if scenario is not None:
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
        else:
            sim = simulated_robot(session, system, typemap, bindings, style)
        if stop is not None:
            _serve(sim, Outcomes(system, failure_rate=rate, seed=seed), duration, seed, stop)
            return 0
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


def file_kind(path: Path, text: str) -> str:
    """``scenario`` or ``system``; a pilot run is a one-line error that names the commands that play it."""
    if is_pilot_run(text):
        run = parse_pilot_run(text, str(path))
        system = path.parent / run.system
        shown = os.path.relpath(system) if not system.is_absolute() else str(system)
        raise SourceError.at(str(path), locate(text, ("pilot",)), f"a pilot run, not a scenario or a system file: "
                                                                  f"`skinet demo {path}` plays it; to drive a "
                                                                  f"simulated robot yourself, `skinet run {shown} "
                                                                  f"--simulate` and `skinet goal` (docs/pilot.md)")
    return "system" if isinstance(parse_toml(text, str(path)).get("system"), dict) else "scenario"


def _serve(robot: Simulator, outcomes: Outcomes, duration: float, seed: int, stop: threading.Event) -> None:
    """``--self-ending``: serve ``robot``, its skills ending by themselves, until ``stop`` (SIGINT, SIGTERM);
    a line on standard output per start and per end, as they come."""
    from services.simulator.world import End, self_ending

    sim = self_ending(robot, outcomes, duration)  # before a start can come: its samples' errors stop it first

    def ended(end: End) -> None:
        print(f"end   {end} {end.id}" + ("" if end.ok else " (it had stopped already)"), flush=True)

    robot.on_start.append(lambda skillset, skill, id_: print(f"start {skillset}:{skill} {id_}", flush=True))
    sim.world.on_end.append(ended)
    what = "bound interfaces" if getattr(robot, "bindings", None) else "skillset managers"
    print(f"python -m services.simulator: the {what} of {robot.system.name}; each skill ends by itself "
          f"{duration:g} s after it starts (failure rate {outcomes.failure_rate:g}, seed {seed}); Ctrl-C stops",
          file=sys.stderr, flush=True)
    try:
        stop.wait()
    finally:
        sim.close()


if __name__ == "__main__":
    sys.exit(main())
