"""``skinet goal``: give a running pilot a goal and follow it to its end (docs/semantics.md §8, issue 24 item 4).

Sends a :class:`~skinet.wire.messages.PilotGoalRequest` on
``skinet/<system>/pilot/goal/<login>``, prints the reply (the plan's answer and
first steps as ``skinet plan`` prints them, or the reason of a rejection), then
one line per change of ``skinet/<system>/pilot/status`` until the goal ends.
Goals are checked here first when the system file is at hand, so a typo is
``FILE:LINE:COL`` before any connection; the pilot checks them again (it has the
live model).  Ctrl-C, from the request on, cancels the goal the pilot accepted;
a cancel leaves the skill the pilot started running, ``--cancel --interrupt``
has the pilot interrupt it too (docs/pilot.md, *Cancelling*).  Exit status: 0
reached, 1 failed or cancelled (or an error: no pilot, no router, a bad system
file), 2 rejected (here, a malformed goal; or by the pilot), as ``--help`` says.
Options and goals may come in any order (``SYSTEM -e ENDPOINT GOAL``).
Cost: one query, then O(1) per status received.
"""

from __future__ import annotations

import argparse
import queue
import signal
import sys
import time
from typing import TYPE_CHECKING, Any

from services.common.zenoh_config import add_zenoh_args
from services.common.options import count, seconds
from chains.pilot_lines import StatusLines, status_line
from skinet_cli.plan import add_goal_args

if TYPE_CHECKING:
    from skinet.wire.messages import PilotGoalReply, PilotStatus

HELP = "give a running pilot a goal (guide or drive) and follow it until it ends (docs/semantics.md §8)"
DESCRIPTION = """\
Send goals to the pilot of a running system (skinet run, or the pilot service)
and follow them. The pilot plans from the live marking as skinet plan does and
either guides (it shows the next command; you send it) or, with --drive, sends
each command to the skillset managers itself, only after the monitor's check
allows it under the strict policy. The reply (the plan's answer and its first
steps) is printed, then one line per change of the pilot's status (state, next
command, moves left, retries, commands sent) until the goal ends. Ctrl-C
cancels the goal. Exit status: 0 reached, 1 failed or cancelled (or no pilot,
no router), 2 rejected (a malformed goal, a goal with no plan, another goal
running without --replace, a login that may not send goals). With --cancel,
--pause, --resume, --set-mode or --confirm: 0 done, 2 rejected (no goal runs);
--cancel --interrupt: 1 when a skill could not be interrupted."""
EPILOG = """\
goals (as in skinet plan):
  reach FORMULA                      a marking where FORMULA holds (the property language)
  run SKILLSET:SKILL                 start SKILL and have it end in a success mode
  run SKILLSET:SKILL.success.MODE    ... in that success mode

examples, with a robot connected to `skinet run skillsets/spot_arm.toml --listen tcp/127.0.0.1:7447`
(tests/services/test_goal.py runs them all, in order):
  skinet goal skillsets/spot_arm.toml "reach spot:Standing and manipulator:RD" --drive -e tcp/127.0.0.1:7447
  skinet goal spot_arm "run spot:go_to_waypoint" --drive -e tcp/127.0.0.1:7447 \\
      --inputs 'go_to_waypoint.target = {x = 12.0, y = 3.5, z = 0.0}'
  skinet goal skillsets/spot_arm.toml --goals skillsets/goals/walk.toml --drive -e tcp/127.0.0.1:7447

guide mode (the pilot shows each command, you send it); from another terminal, pause it, switch it
to drive and resume it (it then sends the commands itself):
  skinet goal spot_arm "reach spot:Sitting" -e tcp/127.0.0.1:7447
  skinet goal spot_arm --pause -e tcp/127.0.0.1:7447
  skinet goal spot_arm --set-mode drive -e tcp/127.0.0.1:7447
  skinet goal spot_arm --resume -e tcp/127.0.0.1:7447

a skill the pilot started that ended while nobody could see it (a monitor restart, a link down) and
whose outcome the resources cannot tell pauses it with 'outcome unknown'; answer how it ended:
  skinet goal spot_arm --confirm success -e tcp/127.0.0.1:7447

a cancel (--cancel, Ctrl-C) leaves the skill the pilot started running: a walk goes on to its waypoint.
With --interrupt the pilot also sends that skill's interrupt once the check allows it (never the
interrupt of a skill someone else started), and says what came of it:
  skinet goal spot_arm --cancel --interrupt -e tcp/127.0.0.1:7447

Through a router with logins, log in as an operator-role user (--user operator --password-file
~/.config/skinet/secrets/operator.password, or --zenoh-config from skinet client-config --user
operator): the router lets no other user send goals, and says nothing to them (no pilot answers)."""

EXIT_REACHED, EXIT_ENDED, EXIT_REJECTED = 0, 1, 2
POLL = 0.2  # seconds between looks at Ctrl-C while waiting for a status
CANCEL_WAIT = 3.0  # seconds to wait for the pilot's `cancelled` after it answered the cancel
CANCEL_RETRY = 1.0  # seconds between cancels the pilot did not answer (a router restarting)
GONE_GRACE = 5.0  # seconds the pilot's token may stay away, this session linked, before it is called stopped


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("goal", help=HELP, description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter, intermixed=True)  # goals after options too
    c.add_argument("system", metavar="SYSTEM",
                   help="system file (.toml: the goals are checked here first) or system name")
    add_goal_args(c)  # as skinet plan's; a --goals file is sent as its text, so errors come back as FILE:LINE:COL
    c.add_argument("--drive", action="store_true",
                   help="the pilot sends the commands itself (default: guide, it shows each one and you send it)")
    c.add_argument("--replace", action="store_true", help="replace a goal that runs (else the pilot rejects the new one)")
    c.add_argument("--recover", action="store_true",
                   help="from a state outside Safe (a property violated or forced), let the pilot first send one of "
                        "the commands that lead back into Safe, then plan again (else such a goal is rejected, with "
                        "those commands named)")
    c.add_argument("--max-retries", type=count(1, 100), default=3, metavar="N",
                   help="failures of one skill after which the goal fails (default: 3)")
    ops = c.add_mutually_exclusive_group()
    ops.add_argument("--cancel", dest="op", action="store_const", const="cancel",
                     help="cancel the goal that runs; a skill it runs goes on (a walk ends where it ends) unless "
                          "--interrupt")
    ops.add_argument("--pause", dest="op", action="store_const", const="pause",
                     help="pause the goal that runs (no command is sent until --resume)")
    ops.add_argument("--resume", dest="op", action="store_const", const="resume", help="resume a paused goal")
    ops.add_argument("--set-mode", choices=("guide", "drive"), metavar="MODE",
                     help="switch the goal that runs to guide or drive")
    ops.add_argument("--confirm", choices=("success", "failure", "rerun"), metavar="ANSWER",
                     help="answer the pilot paused with 'outcome unknown' (a skill ended unseen): success or "
                          "failure (how it ended), or rerun (it did not do its work: start it again)")
    c.add_argument("--interrupt", action="store_true",
                   help="with --cancel: the pilot also interrupts the skills it started for the goal that still run "
                        "(never one someone else started), each once the check allows it, as any command it sends; "
                        "one line per change until each is interrupted or ended (exit 0), or not (exit 1)")
    c.add_argument("--timeout", type=seconds(), default=10.0,
                   help="seconds to wait for the pilot's reply (it plans first), and with --cancel --interrupt for "
                        "what came of the interrupts (default: 10)")
    add_zenoh_args(c)
    c.set_defaults(func=cmd_goal, op=None)


def cmd_goal(args: argparse.Namespace) -> int:
    from services.common.goals import NoPilot, ask_pilot
    from services.common.zenoh_config import (
        check_connected, client_name, config_from_args, open_session, said_at_the_end, wait_connected,
    )
    from services.dashboard.observer import resolve_system
    from skinet.errors import SkinetError
    from skinet.files.read import read_text
    from skinet.wire.messages import PilotGoalReply, PilotGoalRequest

    name, system = resolve_system(args.system)  # a bad system file: an error (exit 1), not a rejected goal
    op = "mode" if args.set_mode else "confirm" if args.confirm else args.op
    if args.interrupt and op != "cancel":
        return _rejected_here(SkinetError("--interrupt goes with --cancel: it interrupts what the cancelled goal "
                                          "started"))
    request = PilotGoalRequest(system=name, op=op or "goal", mode=args.set_mode or ("drive" if args.drive else "guide"),
                               answer=args.confirm, interrupt=args.interrupt)
    if op is None:
        mission = read_text(args.goals_file) if args.goals_file else None  # unreadable: an error (exit 1)
        try:
            request = request.model_copy(update=_goal_fields(args, system, mission))
        except SkinetError as exc:  # a malformed goal, refused here as the pilot refuses it (the help: exit 2)
            return _rejected_here(exc)
    elif args.goals or args.goals_file or args.inputs:
        return _rejected_here(SkinetError(f"--{'set-mode' if op == 'mode' else op} takes no goals: it acts on the "
                                          "goal that runs"))
    config = config_from_args(args, command=True)
    session = open_session(config, said_at_the_end)  # an endpoint still unreached is the error, when no pilot answers

    def ask(request: PilotGoalRequest, timeout: float = args.timeout) -> PilotGoalReply:
        """The pilot's reply; with none, an endpoint still unreached is the reason given, else no pilot."""
        try:
            return ask_pilot(session, request, client_name(config), timeout)
        except NoPilot:
            check_connected(session, config)
            raise

    try:
        wait_connected(session, config, min(args.timeout, 2.0))
        if args.interrupt:
            follower = _Follower(session, name)  # before the request: no change is missed
            try:
                return _operate(session, request, ask, follower, args.timeout)
            finally:
                follower.close()
        if op is not None:
            return _operate(session, request, ask)
        follower = _Follower(session, name)  # before the request: no change is missed
        # Ctrl-C is noted, not raised: one that comes while the pilot plans (Zenoh's get holds it until the reply
        # is in) or before the follower starts still cancels the goal the reply accepted.
        ctrl_c: list[float] = []
        previous = signal.signal(signal.SIGINT, lambda *_: ctrl_c.append(time.monotonic()))
        try:
            reply = ask(request)
            if not reply.accepted:
                print(f"goal rejected by the pilot: {reply.reason}", file=sys.stderr)
                return EXIT_REJECTED
            _print_reply(reply, request.mode)
            said: list[bool] = []
            return follower.follow(reply.goal_id, lambda: _cancel(name, ask, said), ctrl_c)
        finally:
            signal.signal(signal.SIGINT, previous)
            follower.close()
    finally:
        session.close()


def _rejected_here(exc: Exception) -> int:
    """A request refused before it is sent (a malformed goal, goals beside an operation): its one line, and
    the status of a rejected goal."""
    from skinet.errors import SourceError

    print(str(exc) if isinstance(exc, SourceError) else f"skinet: error: {exc}", file=sys.stderr)
    return EXIT_REJECTED


def _goal_fields(args: argparse.Namespace, system: Any, mission: str | None) -> dict[str, Any]:
    """The request's goals, mission (the ``--goals`` file's text) and inputs; checked first against ``system``
    (when the file is at hand)."""
    from skinet.errors import SkinetError
    from skinet.files.toml import parse_toml
    from skinet_cli.plan import read_goals

    if not args.goals and not args.goals_file:
        raise SkinetError("no goals: give GOAL arguments (e.g. \"reach spot:Standing\") or --goals FILE "
                          "(or --cancel, --pause, --resume, --set-mode, --confirm for the goal that runs)")
    if system is not None:
        read_goals(argparse.Namespace(system=args.system, goals_file=args.goals_file, inputs=args.inputs,
                                      goals=args.goals), system)
    fields: dict[str, Any] = {"goals": list(args.goals), "replace": args.replace, "max_retries": args.max_retries,
                              "recover": args.recover}
    if args.inputs is not None:
        fields["inputs"] = parse_toml(args.inputs, "<--inputs>")
    if mission is not None:
        fields["mission"], fields["mission_name"] = mission, args.goals_file
    return fields


def _operate(session: Any, request: Any, ask: Any, follower: _Follower | None = None, timeout: float = 0.0) -> int:
    """Cancel, pause, resume or switch mode: print the pilot's reply (``ask(request)``) and its status; a cancel
    with interrupt: the changes of its status, through ``follower``, until the interrupts ended (``timeout``)."""
    from services.common.goals import pilot_status

    reply = ask(request)
    what = f"mode {request.mode}" if request.op == "mode" else \
        f"confirm {request.answer}" if request.op == "confirm" else request.op
    if not reply.accepted:
        print(f"{what} rejected by the pilot: {reply.reason}", file=sys.stderr)
        return EXIT_REJECTED
    print(f"{what}: done (goal {reply.goal_id})" if reply.goal_id else f"{what}: done", flush=True)
    if follower is not None:
        return follower.interrupts(reply.goal_id, timeout)
    status = pilot_status(session, request.system)
    if status is not None:
        print(status_line(status))
    return 0


def _cancel(system: str, ask: Any, said: list[bool]) -> bool:
    """Ask the pilot to cancel; whether it answered (no answer: the router may be restarting, ask again)."""
    from skinet.errors import SkinetError
    from skinet.wire.messages import PilotGoalRequest

    if not said:
        said.append(True)
        print("cancelled by Ctrl-C: asking the pilot to cancel the goal", flush=True)
    try:
        reply = ask(PilotGoalRequest(system=system, op="cancel"), CANCEL_WAIT)
    except SkinetError as exc:  # no pilot answered, or the router is not reached
        print(f"the pilot did not answer the cancel ({exc}): asking again", file=sys.stderr, flush=True)
        return False
    if not reply.accepted:
        print(f"the pilot did not cancel: {reply.reason}", file=sys.stderr)
    return True


def _print_reply(reply: PilotGoalReply, mode: str) -> None:
    from skinet_cli.plan import answer_text, step_lines

    how = "the pilot sends each command" if mode == "drive" else "the pilot shows each command, you send it"
    print(f"goal {reply.goal_id} accepted ({mode} mode: {how})")
    if reply.answer is not None:
        print(answer_text(reply.answer, reply.moves))
    if reply.steps:
        print("steps:")
        print("\n".join(step_lines(reply.steps, "  ")))
    sys.stdout.flush()


class _Follower:
    """The pilot's status changes and the pilots' liveliness, queued for the main thread (which sees Ctrl-C).

    A pilot's token that goes away is not yet a pilot that stopped: a router restart takes every token
    away until the sessions are linked again.  The pilot is called stopped only when this session is
    linked to a router (or a peer) and the token has stayed away ``GONE_GRACE`` seconds.  The link is
    looked at every ``POLL`` seconds: its loss is said once, and its return asks the pilot's status again."""

    def __init__(self, session: Any, system: str):
        import zenoh

        from skinet.wire import keys

        self.session, self.system = session, system
        self.queue: queue.Queue[PilotStatus | tuple[bool, str]] = queue.Queue()  # a status, or (token there?, pilot)
        self._sub = session.declare_subscriber(keys.pilot_status(system), self._on_status)
        self._tokens = session.liveliness().declare_subscriber(
            keys.alive(system, "pilot", "*"),
            lambda s: self.queue.put((s.kind == zenoh.SampleKind.PUT, str(s.key_expr).rsplit("/", 1)[-1])),
            history=True)  # the tokens there now: a subscriber that never saw one may miss its deletion

    def _on_status(self, sample: Any) -> None:
        from skinet.wire.codec import DecodeError, decode
        from skinet.wire.messages import PilotStatus

        try:
            status = decode(sample.payload.to_bytes(), PilotStatus)
        except DecodeError:
            return
        if status.system == self.system:
            self.queue.put(status)

    def follow(self, goal_id: int, cancel: Any, ctrl_c: list[float]) -> int:
        """Print the changes of goal ``goal_id`` until it ends.  ``ctrl_c`` grows at each Ctrl-C: the first
        calls ``cancel`` (asked again each second until the pilot answers: the router may be restarting)
        and waits for the end, a second one gives up waiting (KeyboardInterrupt)."""
        from services.common.goals import pilot_status

        now = pilot_status(self.session, self.system)  # in case it ended before the subscriber's first sample
        if now is not None:
            self.queue.put(now)
        lines = StatusLines()
        seqs: dict[str, int] = {}
        ours = ""  # the pilot instance following the goal, once a status of it came
        answered: float | None = None  # when the pilot answered the cancel
        asked = 0.0  # when the cancel was last asked
        gone: float | None = None  # since when the pilot's token is away while this session is linked
        unlinked = False  # the link to the router is down (said once per outage)
        while True:
            if len(ctrl_c) > 1:
                raise KeyboardInterrupt
            if ctrl_c and answered is None and time.monotonic() - asked >= CANCEL_RETRY:
                asked = time.monotonic()
                if cancel():
                    answered = time.monotonic()
            try:
                status = self.queue.get(timeout=POLL)
            except queue.Empty:
                if answered is not None and time.monotonic() > answered + CANCEL_WAIT:
                    print("the pilot did not report the goal cancelled", file=sys.stderr)
                    return EXIT_ENDED
                linked = self._linked()
                if linked == unlinked:  # the link went down, or came back
                    unlinked = not linked
                    if unlinked:
                        print("the link to the router is down: waiting for it (Ctrl-C cancels the goal)",
                              file=sys.stderr, flush=True)
                    else:
                        again = pilot_status(self.session, self.system)  # what it said while the link was down
                        if again is not None:
                            self.queue.put(again)
                if gone is not None and time.monotonic() - gone >= GONE_GRACE:
                    if not linked:
                        gone = time.monotonic()  # nothing can be known of the pilot now: wait for the link
                    elif self._pilots(ours):
                        gone = None
                    else:
                        print(f"the pilot stopped before goal {goal_id} ended", file=sys.stderr)
                        return EXIT_ENDED
                continue
            if isinstance(status, tuple):  # a pilot's token came or went: ours (or, not knowing ours yet, any)?
                there, pilot = status
                if ours and pilot != ours:
                    continue
                if there:
                    gone = None
                elif gone is None:
                    gone = time.monotonic()
                continue
            if status.goal_id < goal_id or status.seq <= seqs.get(status.pilot, -1):
                continue  # an earlier goal's, or an older copy
            seqs[status.pilot] = status.seq
            ours = ours or (status.pilot if status.goal_id == goal_id else "")
            # a status does not bring a pilot back: one sent before its token went may come after it (CI saw
            # the follow wait for ever); the look at the tokens after GONE_GRACE says whether it is there
            if status.goal_id > goal_id:
                print(f"goal {goal_id} was replaced by goal {status.goal_id}"
                      + (f" of {status.client}" if status.client else ""), file=sys.stderr)
                return EXIT_ENDED
            line = lines.line(status)
            if line is not None:
                print(line, flush=True)
            if status.state in ("reached", "failed", "cancelled"):
                return EXIT_REACHED if status.state == "reached" else EXIT_ENDED

    def interrupts(self, goal_id: int, timeout: float) -> int:
        """After goal ``goal_id`` was cancelled with interrupt: one line per change of its status until every
        skill to interrupt has its outcome (``PilotStatus.interrupts``); 0 when each was interrupted or had
        ended (or none ran), 1 when one was not, or is still open after ``timeout`` seconds."""
        from services.common.goals import pilot_status
        from skinet.wire.messages import OPEN_INTERRUPTS

        now = pilot_status(self.session, self.system)
        if now is not None:
            self.queue.put(now)
        lines = StatusLines()
        last: PilotStatus | None = None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                status = self.queue.get(timeout=min(POLL, max(0.0, deadline - time.monotonic())))
            except queue.Empty:
                continue
            if isinstance(status, tuple) or status.goal_id != goal_id or status.state != "cancelled" or \
                    (last is not None and status.pilot == last.pilot and status.seq <= last.seq):
                continue
            last = status
            line = lines.line(status)
            if line is not None:
                print(line, flush=True)
            if not any(s in OPEN_INTERRUPTS for s in status.interrupts.values()):
                return EXIT_REACHED if all(s in ("interrupted", "ended") for s in status.interrupts.values()) \
                    else EXIT_ENDED
        still = [n for n, s in (last.interrupts if last is not None else {}).items() if s in OPEN_INTERRUPTS]
        print(f"the pilot has not interrupted {', '.join(still) or 'the skills it started'} within {timeout:g} s; "
              "it goes on trying until a new goal is set", file=sys.stderr)
        return EXIT_ENDED

    def _linked(self) -> bool:
        """Whether this session is linked to a router or a peer now."""
        info = self.session.info
        return bool(list(info.routers_zid()) or list(info.peers_zid()))

    def _pilots(self, pilot: str) -> bool:
        """Whether the token of ``pilot`` (any pilot when '') is there."""
        from skinet.wire import keys

        return any(r.ok is not None for r in self.session.liveliness().get(
            keys.alive(self.system, "pilot", pilot or "*"), timeout=1.0))

    def close(self) -> None:
        from services.common.zenoh_config import undeclare

        undeclare(self._sub, self._tokens)
