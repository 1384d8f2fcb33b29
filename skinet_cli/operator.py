"""``skinet dashboard``, ``skinet watch`` and ``skinet check``: operator views of any running
deployment, as read-only Zenoh observers (docs/semantics.md §7).  Arguments only; Zenoh and the web
server are imported when a command runs."""

from __future__ import annotations

import argparse

from services.common.zenoh_config import add_zenoh_args
from skinet.wire.messages import MAX_CHECK_WAIT
from services.common.options import key_name, seconds, seconds_within


def add_parsers(sub: argparse._SubParsersAction) -> None:
    from services.dashboard.app import add_dashboard_args

    c = sub.add_parser("dashboard", help="live web dashboard of a running system (served on 127.0.0.1:8080)",
                       description="Serve a live web page of a running system: skillsets, properties, unsafe "
                                   "commands with kind, steps and witness, predictions, state space, violations "
                                   "and a timeline, observed on Zenoh; and a goal box that gives goals to the "
                                   "system's pilot (guide or drive, pause, resume, cancel; docs/semantics.md §8) under this "
                                   "process's login (--user: only operator-role users may send goals).")
    add_dashboard_args(c)
    c.set_defaults(func=cmd_dashboard)

    c = sub.add_parser("watch", help="terminal live view of a running system (any deployment)",
                       description="Follow a running system's monitor through Zenoh and show the operator view "
                                   "(skillsets, properties, unsafe transitions, predictions, services, violations, "
                                   "divergences, the pilot's status): redrawn on a terminal; in a pipe, one line per "
                                   "step, per divergence and per change of the pilot's status.")
    c.add_argument("system", metavar="SYSTEM_NAME", type=key_name("system name"),
                   help="system name, as in skinet/<system>/... keys")
    c.add_argument("--once", action="store_true", help="print one view (after a fresh prediction) and exit")
    c.add_argument("--duration", type=seconds(), help="stop after this many seconds")
    c.add_argument("--wait", type=seconds(), default=5.0,
                   help="seconds to wait for the system's monitor before giving up (default: 5)")
    add_zenoh_args(c)
    c.set_defaults(func=cmd_watch)

    c = sub.add_parser("check", help="ask a running monitor whether a command is safe now (skinet/<system>/check)",
                       description="Ask the monitor's command check about SKILLSET:TRANSITION at the live "
                                   "marking: allow, warn or deny (the monitor's policy, or --policy) with the "
                                   "reasons. While the monitor cannot vouch for the live marking (a skillset "
                                   "syncing or lost) or the prediction is pending, the answer is at least warn "
                                   "(state_unknown, prediction_pending); --wait lets it wait for them first. "
                                   "A transition that cannot fire at the live marking answers NOT FIRABLE with "
                                   "the decision it would get. Exit status: 0 allow, 3 warn, 4 deny, 5 not "
                                   "firable now, 1 error (unknown name, no monitor, no router).")
    c.add_argument("system", metavar="SYSTEM_NAME", type=key_name("system name"),
                   help="system name, as in skinet/<system>/... keys")
    c.add_argument("command", metavar="SKILLSET:TRANSITION", help="e.g. spot:go_to_waypoint.start")
    c.add_argument("--json", action="store_true", help="print the CheckReply as JSON")
    c.add_argument("--timeout", type=seconds(), default=2.0,
                   help="seconds to wait for the monitor's answer, beyond --wait (default: 2)")
    c.add_argument("--wait", type=seconds_within(0, MAX_CHECK_WAIT), default=0.0, metavar="S",
                   help="let the monitor wait up to S seconds for a synced state and a fresh prediction before it "
                        f"answers (default: 0, answer at once; at most {MAX_CHECK_WAIT:g})")
    c.add_argument("--policy", metavar="P",
                   help="answer under this policy instead of the monitor's: warn, strict, or KIND=ACTION,...")
    add_zenoh_args(c)
    c.set_defaults(func=cmd_check)


def cmd_dashboard(args: argparse.Namespace) -> int:
    from services.dashboard.app import serve
    from services.common.cli import stop_on_signals

    return serve(args, stop_on_signals())


def cmd_watch(args: argparse.Namespace) -> int:
    from chains.watch import watch

    return watch(args)


EXIT = {"allow": 0, "warn": 3, "deny": 4}
NOT_FIRABLE = 5  # the command cannot be sent now, whatever its decision


def cmd_check(args: argparse.Namespace) -> int:
    import json
    import time

    from services.common.zenoh_config import (
        check_connected, client_name, config_from_args, open_session, said_at_the_end, wait_connected,
    )
    from services.dashboard.observer import monitored_systems
    from services.monitor.check import parse_command, parse_policy
    from skinet.errors import SkinetError
    from skinet.wire import keys
    from skinet.wire.codec import DecodeError, decode, encode
    from skinet.wire.messages import CheckReply

    try:
        request = parse_command(args.command).model_copy(update={"wait": args.wait, "policy": args.policy})
        if args.policy is not None:
            parse_policy(args.policy)
    except ValueError as exc:
        raise SkinetError(str(exc)) from None
    config = config_from_args(args, command=True)
    key = keys.check(args.system, client_name(config))
    session = open_session(config, said_at_the_end)
    try:
        deadline = time.monotonic() + args.timeout
        wait_connected(session, config, args.timeout)  # an endpoint Zenoh still tries may come up in time
        left = max(0.1, deadline - time.monotonic()) + args.wait  # the monitor may keep it that long
        replies = [r for r in session.get(key, payload=encode(request), timeout=left) if r.ok is not None]
        if not replies:
            check_connected(session, config)
            others = monitored_systems(session)
            raise SkinetError(f"no monitor of system '{args.system}' answered on {key} "
                              f"({'systems with a monitor: ' + ', '.join(others) if others else 'no monitor is reachable'})")
        try:
            reply = decode(replies[0].ok.payload.to_bytes(), CheckReply)
        except DecodeError as exc:
            raise SkinetError(f"undecodable answer on {key}: {exc}") from None
    finally:
        session.close()
    if args.json:
        print(json.dumps(reply.model_dump(mode="json"), indent=2))
    elif not reply.ok:
        print(f"{args.command}: error: {reply.error}" + (f" (candidates: {', '.join(reply.candidates)})"
                                                          if reply.candidates else ""))
    else:
        decision = reply.decision.upper() if reply.decision else "?"
        answer = (f"{decision} at step {reply.seq}" if reply.enabled else
                  f"NOT FIRABLE at step {reply.seq} (not enabled at the live marking; if it were: {decision})")
        print(f"{args.command}: {answer}"
              + (" (STATE NOT LIVE: about the last marking known)" if reply.state_stale else "")
              + (" (prediction stale: explicit and forced constraints only)" if reply.prediction_stale else ""))
        for r in reply.reasons:
            steps = "" if not r.steps else f", within {r.steps} steps"
            via = f" via {' -> '.join(r.witness)}" if r.witness else ""
            why = f" — {r.reason}" if r.reason else ""
            print(f"  {r.property + ': ' if r.property else ''}{r.constraint} ({r.action}){steps}{via}{why}")
        for p in reply.recovers:
            print(f"  restores {p} (violated now)")
    if not reply.ok:
        return 1
    return EXIT.get(reply.decision or "", 1) if reply.enabled else NOT_FIRABLE
