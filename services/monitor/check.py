"""The command check: allow, warn or deny one ``skillset:transition`` now (SPEC §7, §5).

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
"""

from __future__ import annotations

import argparse
import difflib
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

from skinet.net.semantics import steps
from skinet.system import System
from skinet.verify.algorithm1 import CONSTRAINTS, Analysis
from skinet.wire.codec import DecodeError, decode
from skinet.wire.messages import CheckReason, CheckReply, CheckRequest

ACTIONS = ("allow", "warn", "deny")
_STRENGTH = {a: i for i, a in enumerate(ACTIONS)}
KINDS = CONSTRAINTS
PRESETS: dict[str, dict[str, str]] = {
    "warn": {k: "warn" for k in KINDS},
    "strict": {"explicit": "deny", "implicit": "warn", "forced": "deny", "unknown": "warn"},
}
MAX_CANDIDATES = 8


@dataclass(frozen=True)
class Policy:
    """Constraint kind -> action; kinds not listed get ``other``."""

    actions: Mapping[str, str] = field(default_factory=lambda: dict(PRESETS["warn"]))
    other: str = "warn"

    def action(self, constraint: str) -> str:
        return self.actions.get(constraint, self.other)

    def __str__(self) -> str:
        return ",".join(f"{k}={a}" for k, a in self.actions.items())


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
        actions[kind] = action
    return Policy(actions)


def add_policy_arg(parser: argparse.ArgumentParser) -> None:
    """``--check-policy`` (default ``$SKINET_CHECK_POLICY`` or ``warn``), parsed into a :class:`Policy`."""
    def policy(text: str) -> Policy:
        try:
            return parse_policy(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parser.add_argument("--check-policy", type=policy, default=os.environ.get("SKINET_CHECK_POLICY", "warn"),
                        help="answers of skinet/<system>/check: warn (warn on every constraint, deny nothing), "
                             "strict (deny explicit and forced), or KIND=ACTION,... e.g. strict,implicit=deny "
                             "(default: $SKINET_CHECK_POLICY or warn)")


def parse_command(text: str) -> CheckRequest:
    """``skillset:transition`` as a request; ``ValueError`` when there is no ``:``."""
    skillset, sep, transition = text.strip().partition(":")
    if not sep or not skillset or not transition:
        raise ValueError(f"command '{text}' is not of the form skillset:transition (e.g. spot:teleop.start)")
    return CheckRequest(skillset=skillset, transition=transition)


class Checker:
    """Answers :class:`CheckRequest` for one system under one policy (not thread-safe)."""

    def __init__(self, system: System, policy: Policy | None = None):
        self.system = system
        self.policy = policy or Policy()
        self._policy_text = str(self.policy)
        self.transitions = {c.name: sorted({t.name for t in c.net.transitions}) for c in system.components}
        self._known = {c: set(ts) for c, ts in self.transitions.items()}
        self._firable: tuple[object, dict[str, set[str]]] | None = None  # (marking key, firable names)

    def answer(self, request: CheckRequest, analysis: Analysis, key: object, *, seq: int = 0,
               stale: bool = False) -> CheckReply:
        """The reply for ``request`` at the marking of ``analysis`` (``key`` identifies that marking)."""
        ss, tr = request.skillset, request.transition
        base = dict(system=self.system.name, skillset=ss, transition=tr, seq=seq, policy=self._policy_text)
        if ss not in self._known:
            return CheckReply(**base, ok=False, error=f"unknown skillset '{ss}'",
                              candidates=_close(ss, list(self._known)))
        if tr not in self._known[ss]:
            return CheckReply(**base, ok=False, error=f"unknown transition '{tr}' of skillset '{ss}'",
                              candidates=_close(tr, self.transitions[ss]))
        reasons = [
            CheckReason(property=u.property, constraint=u.constraint, action=self.policy.action(u.constraint),
                        controllable=u.controllable, steps=u.steps, witness=list(u.witness), reason=u.reason)
            for u in analysis.operator_unsafe() if u.skillset == ss and u.transition == tr
        ]
        decision = max((r.action for r in reasons), key=_STRENGTH.__getitem__, default="allow")
        recovers = [p for p, rs in analysis.recovery.items() if any(r.skillset == ss and r.transition == tr for r in rs)]
        return CheckReply(**base, ok=True, decision=decision, reasons=reasons,
                          enabled=tr in self._firable_at(analysis, key)[ss], violated=list(analysis.violated),
                          recovers=recovers, prediction_stale=stale)

    def _firable_at(self, analysis: Analysis, key: object) -> dict[str, set[str]]:
        if self._firable is None or self._firable[0] != key:
            names = {c.name: {t.name for t, _ in steps(c.net, analysis.marking[c.name])}
                     for c in self.system.components}
            self._firable = (key, names)
        return self._firable[1]


def _close(name: str, known: list[str]) -> list[str]:
    """Known names close to ``name`` (all of them, up to a few, when none is close)."""
    close = difflib.get_close_matches(name, known, n=MAX_CANDIDATES, cutoff=0.6)
    return close or sorted(known)[:MAX_CANDIDATES]


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
