"""``python -m services.pilot SYSTEM.toml [zenoh flags]``: the pilot as a process (docs/semantics.md §8, issue 24)."""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence

from services.common.cli import (
    add_instance_arg, add_log_arg, add_ros_key_args, key_style, one_line_errors, setup_logging,
)
from services.common.memory import add_memory_arg, memory_limit
from services.common.zenoh_config import add_zenoh_args, client_name, config_from_args, open_session
from services.common.cli import stop_on_signals
from services.pilot.service import start_pilot
from skinet.system.load import load_typemap
from skinet.wire import keys
from services.common.options import (
    ArgumentParser, add_no_properties_arg, add_outcome_timeout_arg, budget, load_live_system, require_properties, seconds,
)


def build_parser() -> ArgumentParser:
    p = ArgumentParser(
        prog="python -m services.pilot",
        description="SkiNet Live pilot: takes goals on skinet/<system>/pilot/goal/<client>, follows the monitor's "
                    "live state, and guides the operator (the next command) or drives the skillset managers "
                    "itself, sending only commands the monitor's strict check allows. Its status is on "
                    "skinet/<system>/pilot/status. Send goals with a PilotGoalRequest (see docs/pilot.md).",
    )
    p.add_argument("system", help="system file (.toml), e.g. skillsets/spot_arm.toml (its type map gives the "
                                  "managers' message types)")
    add_instance_arg(p)
    p.add_argument("--budget", type=budget(), default=1.0,
                   help="planning budget per goal, seconds (default: 1); past it the plan is unknown and the goal fails")
    add_memory_arg(p, "past it the plan is unknown and the goal fails")
    p.add_argument("--response-timeout", type=seconds(), default=5.0,
                   help="seconds a manager has to react to a command before the goal fails (default: 5)")
    add_outcome_timeout_arg(p)
    add_ros_key_args(p)
    add_no_properties_arg(p)
    add_log_arg(p)
    add_zenoh_args(p)
    return p


@one_line_errors("python -m services.pilot")
def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args)
    system, _ = load_live_system(args.system)
    require_properties(system, args.system, args.no_properties)
    typemap = load_typemap(args.system)
    config = config_from_args(args)
    log = logging.getLogger("skinet.pilot")
    stop = stop_on_signals()
    session = open_session(config)
    try:
        pilot = start_pilot(session, system, instance=args.instance, response_timeout=args.response_timeout,
                            budget=args.budget, client=client_name(config), typemap=typemap,
                            style=key_style(args), outcome_timeout=args.outcome_timeout,
                            memory_limit=memory_limit(args))
        log.info("pilot %s of %s: goals on %s, status on %s", pilot.instance, system.name,
                 keys.pilot_goal(system.name, "<client>"), keys.pilot_status(system.name))
        while not stop.wait(0.5):
            pass
        pilot.close()
        log.info("stopped")
    finally:
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
