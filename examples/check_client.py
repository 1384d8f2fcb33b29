"""Ask SkiNet Live before every skill start: a guarded skill-manager client (docs/semantics.md §7).

A skill-manager client (what an operator GUI does) starts a skill by publishing
a ``Skill<K>Request`` on the manager's ``skill/<k>/request`` topic; over Zenoh
(zenoh-bridge-ros2dds layout) that is a CDR payload on
``<manager>/<skillset>/skill/<k>/request``.  :class:`GuardedSkillClient` wraps
such a client: before each start it asks the monitor's command check
``skinet/<system>/check/<client>`` (``<client>``: its router login) and

- ``allow``: sends the request;
- ``warn``: asks ``confirm(reply)`` (here: refuse unless ``--force``), then sends or not;
- ``deny`` (the monitor's strict policy), no answer or an error: does not send.

It asks the monitor to wait up to ``--wait`` seconds (default 2) for a synced state
and a fresh prediction: without them the answer is at least ``warn``
(``state_unknown``, ``prediction_pending``; docs/semantics.md §7).

    python examples/check_client.py skillsets/spot_arm.toml spot:init_power.start spot:teleop.start \\
        --connect tcp/127.0.0.1:7447 --user observer --password observer-demo-password

A user who may publish the managers' request topics is needed to actually start
skills through the shipped router (``robot``); with ``observer`` the check works
and the router drops the request.
"""

from __future__ import annotations

import argparse
import sys
import uuid
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import zenoh  # noqa: E402

from services.common.zenoh_config import add_zenoh_args, client_name, config_from_args, open_session  # noqa: E402
from skinet.errors import SkinetError  # noqa: E402
from skinet.system.load import load_system, load_typemap
from skinet.ros.interfaces import skill_topic  # noqa: E402
from skinet.ros.keys import KeyStyle, manager_topics  # noqa: E402
from skinet.ros.typestore import build_typestore, default_instance, encode  # noqa: E402
from skinet.system.model import System  # noqa: E402
from skinet.wire import keys  # noqa: E402
from skinet.wire.codec import DecodeError, decode  # noqa: E402
from skinet.wire.codec import encode as encode_message  # noqa: E402
from skinet.wire.messages import CheckReply, CheckRequest  # noqa: E402


class SkillManagerClient:
    """Starts skills on the managers of ``system`` (what a GUI does; no check)."""

    def __init__(self, session: zenoh.Session, system: System, typemap: dict[str, str], style: KeyStyle = KeyStyle()):
        self.session, self.system, self.style = session, system, style
        self._stores = {c.name: build_typestore(c.skillset, typemap) for c in system.components}
        self._topics = {c.name: {t.topic: t for t in manager_topics(c.skillset)} for c in system.components}

    def start(self, skillset: str, skill: str, **inputs: object) -> str:
        """Publish a start request; returns its id."""
        comp = self.system.component(skillset)
        topic = self._topics[skillset][skill_topic(comp.skillset, skill, "request")]
        store = self._stores[skillset]
        request_id = uuid.uuid4().hex[:8]
        payload = encode(store, topic.typename, default_instance(store, topic.typename, id=request_id, **inputs))
        self.session.put(self.style.key(comp.manager, topic, store), payload,
                         congestion_control=zenoh.CongestionControl.BLOCK)
        return request_id


class CommandRefused(Exception):
    """The start was not sent; ``reply`` is the monitor's answer (None: nobody answered)."""

    def __init__(self, message: str, reply: CheckReply | None):
        super().__init__(message)
        self.reply = reply


class GuardedSkillClient:
    """:class:`SkillManagerClient` that asks ``skinet/<system>/check`` before every start."""

    def __init__(self, client: SkillManagerClient, confirm: Callable[[CheckReply], bool], timeout: float = 1.0,
                 login: str = keys.LOCAL_CLIENT, wait: float = 2.0):
        """``login``: the session's router user, the client chunk of the check key; ``wait``: seconds the
        monitor may wait for a synced state and a fresh prediction."""
        self.client, self.confirm, self.timeout, self.login, self.wait = client, confirm, timeout, login, wait

    def check(self, skillset: str, transition: str) -> CheckReply | None:
        request = encode_message(CheckRequest(skillset=skillset, transition=transition, wait=self.wait))
        for reply in self.client.session.get(keys.check(self.client.system.name, self.login), payload=request,
                                             timeout=self.timeout + self.wait):
            if reply.ok is not None:
                try:
                    return decode(reply.ok.payload.to_bytes(), CheckReply)
                except DecodeError:
                    return None
        return None

    def start(self, skillset: str, skill: str, **inputs: object) -> tuple[str, CheckReply]:
        """Start ``skill`` if the monitor allows it (or the operator confirms a warning)."""
        reply = self.check(skillset, f"{skill}.start")
        if reply is None:
            raise CommandRefused("no monitor answered the check: not sent", None)
        if not reply.ok:
            raise CommandRefused(f"check failed: {reply.error}", reply)
        if reply.decision == "deny" or (reply.decision == "warn" and not self.confirm(reply)):
            raise CommandRefused(f"{reply.decision}: {explain(reply)}", reply)
        return self.client.start(skillset, skill, **inputs), reply


def explain(reply: CheckReply) -> str:
    parts = [f"{r.property} {r.constraint}".strip() + (f" within {r.steps} steps" if r.steps else "")
             + (f" via {' -> '.join(r.witness)}" if r.witness else "") for r in reply.reasons]
    return "; ".join(parts) or "no property at risk"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Start skills, asking SkiNet Live's command check first.")
    parser.add_argument("system", help="system file (.toml)")
    parser.add_argument("commands", nargs="+", metavar="SKILLSET:SKILL.start", help="skills to start, in order")
    parser.add_argument("--force", action="store_true", help="send warned commands anyway (never denied ones)")
    parser.add_argument("--wait", type=float, default=2.0,
                        help="seconds the monitor may wait for a synced state and a fresh prediction (default: 2)")
    add_zenoh_args(parser)
    args = parser.parse_args(argv)
    try:
        system, _ = load_system(args.system)
        typemap = load_typemap(args.system)
        config = config_from_args(args)
        session = open_session(config)
    except SkinetError as exc:
        print(f"check_client: error: {exc}", file=sys.stderr)
        return 1
    status = 0
    try:
        guarded = GuardedSkillClient(SkillManagerClient(session, system, typemap), lambda _reply: args.force,
                                     login=client_name(config), wait=args.wait)
        for command in args.commands:
            skillset, _, transition = command.partition(":")
            skill, _, kind = transition.partition(".")
            if kind != "start" or skillset not in {c.name for c in system.components}:
                print(f"{command}: not a skill start of this system (skillset:skill.start)", file=sys.stderr)
                status = 1
                continue
            try:
                request_id, reply = guarded.start(skillset, skill)
            except CommandRefused as exc:
                print(f"{command}: NOT SENT ({exc})")
                if exc.reply is not None and exc.reply.candidates:
                    print(f"  did you mean: {', '.join(exc.reply.candidates)}")
                status = 1
                continue
            print(f"{command}: sent (id {request_id}; check: {reply.decision}"
                  + (f", {explain(reply)}" if reply.reasons else "") + ")")
    finally:
        session.close()
    return status


if __name__ == "__main__":
    sys.exit(main())
