"""The client side of the pilot (docs/semantics.md §8): ask its goal queryable, read its status.

Shared by ``skinet goal`` and the dashboard's goal box.  A goal request goes to
``skinet/<system>/pilot/goal/<client>`` where ``client`` is the session's router
login (the router lets user ``U`` ask only under ``U``, and lets only
``operator``-role users ask there at all); no answer is a :class:`NoPilot`
error whose message says where it asked and what to check: nobody there (the
query ends at once), or nobody answering within the timeout.
"""

from __future__ import annotations

import time

import zenoh

from skinet.errors import SkinetError
from skinet.files import program
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.messages import PilotGoalReply, PilotGoalRequest, PilotStatus

GOAL_TIMEOUT = 10.0  # seconds for the pilot's reply: it plans before it answers (budget 1 s by default)
TERMINAL = ("reached", "failed", "cancelled")  # a goal's end states


class NoPilot(SkinetError):
    """No pilot answered a goal request (none running, or the router refused the login)."""


def no_pilot_message(system: str, client: str) -> str:
    key = keys.pilot_goal(system, client)
    who = "" if client == keys.LOCAL_CLIENT else (
        f" (or the router refused user '{client}': only operator-role users may send goals)")
    return f"no pilot answers on {key}: is `{program.skinet()} run` or the pilot service running?{who}"


def ask_pilot(session: zenoh.Session, request: PilotGoalRequest, client: str,
              timeout: float = GOAL_TIMEOUT) -> PilotGoalReply:
    """The pilot's reply to ``request`` asked as ``client``; raises :class:`NoPilot` when none comes
    within ``timeout`` seconds and :class:`SkinetError` for an answer that does not decode."""
    key = keys.pilot_goal(request.system, client)
    start = time.monotonic()
    for reply in session.get(key, payload=encode(request), timeout=timeout):
        if reply.ok is None:
            continue
        try:
            return decode(reply.ok.payload.to_bytes(), PilotGoalReply)
        except DecodeError as exc:
            raise SkinetError(f"undecodable answer on {key}: {exc}") from None
    if time.monotonic() - start >= timeout:  # somebody holds the query: a pilot still planning, or frozen
        raise NoPilot(f"no answer on {key} within {timeout:g} s: a pilot still planning may yet take the goal "
                      f"({program.skinet()} goal {request.system} --cancel cancels it)")
    raise NoPilot(no_pilot_message(request.system, client))


def pilot_status(session: zenoh.Session, system: str, timeout: float = 2.0) -> PilotStatus | None:
    """The pilot's last status (its answer on ``skinet/<system>/pilot/status``), None without a pilot."""
    for reply in session.get(keys.pilot_status(system), timeout=timeout):
        if reply.ok is not None:
            try:
                status = decode(reply.ok.payload.to_bytes(), PilotStatus)
            except DecodeError:
                continue
            if status.system == system:
                return status
    return None
