"""The command check: allow, warn or deny one ``skillset:transition`` now (docs/semantics.md §7, §5).

A GUI or a skill-manager client asks ``skinet/<system>/check/<client>`` before it sends a
command.  The answer comes from the monitor's live Algorithm 1 result (the
operator view: properties that hold now, with the latest prediction), so it
costs no exploration: a scan of the unsafe entries of the live marking
(O(U) for U unsafe entries) plus, once per marking, the set of firable
transitions (O(T) per skillset).

Each constraint kind maps to an action (:class:`Policy`); the decision is the
strictest action over the reasons, ``allow`` when there is none.  The default
policy warns on every kind and denies nothing (the paper's assisted run: the
operator decides); ``strict`` denies explicit and forced constraints (the
violation is certain now, or no command can prevent it) and warns on the rest.
A kind the policy does not name (a newer monitor's) is warned about.

The answer never vouches for what the monitor does not know (docs/semantics.md §7): when a
skillset is not ``live`` the reasons include ``state_unknown``, and while the
prediction of the live marking is pending ``prediction_pending``; a policy may
warn or deny on them, never allow.  ``strict`` denies ``state_unknown`` (a
marking that may not be the robot's proves nothing) and warns on
``prediction_pending`` (what strict denies, explicit and forced constraints,
is computed at every event and never waits for a prediction).  A request may
name its own policy (:func:`parse_policy`); names are checked, and close
candidates suggested, outside the monitor's lock and only for names of at most
``MAX_NAME`` characters.
"""

from __future__ import annotations

import argparse
import difflib
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

from skinet.net.semantics import steps
from skinet.system.model import System
from skinet.verify.algorithm1 import CONSTRAINTS, Analysis
from skinet.wire.codec import DecodeError, decode
from skinet.wire.messages import CheckReason, CheckReply, CheckRequest

ACTIONS = ("allow", "warn", "deny")
_STRENGTH = {a: i for i, a in enumerate(ACTIONS)}
STATE_UNKNOWN, PREDICTION_PENDING = "state_unknown", "prediction_pending"
NEVER_ALLOWED = (STATE_UNKNOWN, PREDICTION_PENDING)  # the monitor cannot vouch: at least warn
KINDS = (*CONSTRAINTS, *NEVER_ALLOWED)
PRESETS: dict[str, dict[str, str]] = {
    "warn": {k: "warn" for k in KINDS},
    "strict": {"explicit": "deny", "implicit": "warn", "forced": "deny", "unknown": "warn",
               STATE_UNKNOWN: "deny", PREDICTION_PENDING: "warn"},
}
MAX_CANDIDATES = 8
MAX_NAME = 128  # characters: longer names get no suggestions (difflib is quadratic)
MAX_REQUEST = 4096  # bytes of a check query's payload or parameters; larger ones are refused undecoded


@dataclass(frozen=True)
class Policy:
    """Constraint kind -> action; kinds not listed get ``other``."""

    actions: Mapping[str, str] = field(default_factory=lambda: dict(PRESETS["warn"]))
    other: str = "warn"

    def action(self, constraint: str) -> str:
        return self.actions.get(constraint, self.other)

    @cached_property
    def text(self) -> str:
        return ",".join(f"{k}={a}" for k, a in self.actions.items())

    def __str__(self) -> str:
        return self.text


def parse_policy(text: str) -> Policy:
    """``warn`` (default), ``strict``, or ``KIND=ACTION,...`` on top of ``warn`` (or of a preset
    named first: ``strict,implicit=deny``); raises ``ValueError`` with a one-line reason."""
    actions = dict(PRESETS["warn"])
    for n, part in enumerate(p.strip() for p in text.split(",")):
        if not part:
            continue
        if "=" not in part:
            if n or part not in PRESETS:
                raise ValueError(f"unknown check policy '{part}' (presets: {', '.join(PRESETS)}; "
                                 f"or KIND=ACTION with ACTION one of {', '.join(ACTIONS)})")
            actions = dict(PRESETS[part])
            continue
        kind, _, action = (x.strip() for x in part.partition("="))
        if action not in ACTIONS:
            raise ValueError(f"check policy '{part}': action must be one of {', '.join(ACTIONS)}")
        if not kind:
            raise ValueError(f"check policy '{part}': missing constraint kind")
        if kind in NEVER_ALLOWED and action == "allow":
            raise ValueError(f"check policy '{part}': {kind} can only be warn or deny (the monitor never "
                             "allows what it cannot vouch for)")
        actions[kind] = action
    return Policy(actions)


policy_of = lru_cache(maxsize=64)(parse_policy)  # requests naming a policy: parsed once (thread-safe)


def add_policy_arg(parser: argparse.ArgumentParser) -> None:
    """``--check-policy`` (default ``$SKINET_CHECK_POLICY`` or ``warn``), parsed into a :class:`Policy`."""
    def policy(text: str) -> Policy:
        try:
            return parse_policy(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parser.add_argument("--check-policy", type=policy, default=os.environ.get("SKINET_CHECK_POLICY", "warn"),
                        help="answers of skinet/<system>/check: warn (warn on every constraint, deny nothing), "
                             "strict (deny explicit and forced constraints and a state the monitor cannot vouch "
                             "for), or KIND=ACTION,... e.g. strict,implicit=deny; kinds: " + ", ".join(KINDS) +
                             " (default: $SKINET_CHECK_POLICY or warn)")


def parse_command(text: str) -> CheckRequest:
    """``skillset:transition`` as a request; ``ValueError`` when there is no ``:``."""
    skillset, sep, transition = text.strip().partition(":")
    if not sep or not skillset or not transition:
        raise ValueError(f"command '{text}' is not of the form skillset:transition (e.g. spot:teleop.start)")
    return CheckRequest(skillset=skillset, transition=transition)


class Checker:
    """Answers :class:`CheckRequest` for one system under one policy.

    :meth:`unknown` and :meth:`policy_for` read nothing that changes (call them without
    the monitor's lock); :meth:`answer` caches the firable transitions of the live
    marking (call it under the lock)."""

    def __init__(self, system: System, policy: Policy | None = None):
        self.system = system
        self.policy = policy or Policy()
        self.transitions = {c.name: sorted({t.name for t in c.net.transitions}) for c in system.components}
        self._known = {c: set(ts) for c, ts in self.transitions.items()}
        self._controllable = {(c.name, t.name): t.controllable for c in system.components for t in c.net.transitions}
        self._firable: tuple[object, dict[str, set[str]]] | None = None  # (marking key, firable names)

    def _reply(self, request: CheckRequest, **fields: object) -> CheckReply:
        return CheckReply(system=self.system.name, skillset=_shown(request.skillset),
                          transition=_shown(request.transition), **fields)  # type: ignore[arg-type]

    def unknown(self, request: CheckRequest) -> CheckReply | None:
        """The error reply for an unknown skillset or transition, with close candidates; None when both are known."""
        ss, tr = request.skillset, request.transition
        if ss not in self._known:
            return self._reply(request, ok=False, error=f"unknown skillset '{_shown(ss)}'",
                               candidates=_close(ss, list(self._known)))
        if tr not in self._known[ss]:
            return self._reply(request, ok=False, error=f"unknown transition '{_shown(tr)}' of skillset '{ss}'",
                               candidates=_close(tr, self.transitions[ss]))
        return None

    def policy_for(self, request: CheckRequest) -> Policy | CheckReply:
        """The policy that answers ``request`` (its own, or the monitor's); an error reply for a bad one."""
        if request.policy is None:
            return self.policy
        try:
            return policy_of(request.policy)
        except ValueError as exc:
            return self._reply(request, ok=False, error=str(exc))

    def answer(self, request: CheckRequest, analysis: Analysis, key: object, *, seq: int = 0,
               stale: bool = False, state: tuple[str, float] | None = None,
               policy: Policy | None = None) -> CheckReply:
        """The reply for ``request`` (known names) at the marking of ``analysis`` (``key`` identifies that
        marking); ``stale``: its prediction is pending; ``state``: why and since when a skillset is not live."""
        ss, tr = request.skillset, request.transition
        policy = policy or self.policy
        reasons = [
            CheckReason(property=u.property, constraint=u.constraint, action=policy.action(u.constraint),
                        controllable=u.controllable, steps=u.steps, witness=list(u.witness), reason=u.reason)
            for u in analysis.operator_unsafe() if u.skillset == ss and u.transition == tr
        ]
        controllable = self._controllable[(ss, tr)]
        if state is not None:
            reasons.append(CheckReason(property="", constraint=STATE_UNKNOWN, action=policy.action(STATE_UNKNOWN),
                                       controllable=controllable,
                                       reason=f"the live state is not known, the answer is about the last marking "
                                              f"known: {state[0]}"))
        if stale:
            reasons.append(CheckReason(property="", constraint=PREDICTION_PENDING,
                                       action=policy.action(PREDICTION_PENDING), controllable=controllable,
                                       reason=f"implicit constraints at step {seq} are not known yet: its "
                                              "prediction is pending"))
        decision = max((r.action for r in reasons), key=_STRENGTH.__getitem__, default="allow")
        recovers = [p for p, rs in analysis.recovery.items() if any(r.skillset == ss and r.transition == tr for r in rs)]
        return CheckReply(system=self.system.name, skillset=ss, transition=tr, seq=seq, policy=str(policy), ok=True,
                          decision=decision, reasons=reasons, enabled=tr in self._firable_at(analysis, key)[ss],
                          violated=list(analysis.violated), recovers=recovers, prediction_stale=stale,
                          state_stale=state is not None, state_reason="" if state is None else state[0])

    def _firable_at(self, analysis: Analysis, key: object) -> dict[str, set[str]]:
        if self._firable is None or self._firable[0] != key:
            names = {c.name: {t.name for t, _ in steps(c.net, analysis.marking[c.name])}
                     for c in self.system.components}
            self._firable = (key, names)
        return self._firable[1]


def _close(name: str, known: list[str]) -> list[str]:
    """Known names close to ``name`` (all of them, up to a few, when none is close or ``name`` is too long
    to compare: difflib's cost grows with the square of its length)."""
    close = difflib.get_close_matches(name, known, n=MAX_CANDIDATES, cutoff=0.6) if len(name) <= MAX_NAME else []
    return close or sorted(known)[:MAX_CANDIDATES]


def _shown(name: str) -> str:
    """``name`` as an answer may echo it: cut at ``MAX_NAME`` characters."""
    return name if len(name) <= MAX_NAME else f"{name[:MAX_NAME]}... ({len(name)} characters)"


def request_from(system: str, payload: bytes | None, parameters: str) -> CheckRequest | CheckReply:
    """The request of a query: a msgpack :class:`CheckRequest` payload, else the selector
    parameter ``command=skillset:transition``; an error reply when neither is usable."""
    def error(text: str) -> CheckReply:
        return CheckReply(system=system, skillset="", transition="", ok=False, error=text)

    if payload:
        try:
            return decode(payload, CheckRequest)
        except DecodeError as exc:
            return error(str(exc))
    params = dict(p.partition("=")[::2] for p in parameters.split(";") if p)
    if "command" not in params:
        return error("empty check request: send a CheckRequest payload or the parameter command=skillset:transition")
    try:
        return parse_command(params["command"])
    except ValueError as exc:
        return error(str(exc))
