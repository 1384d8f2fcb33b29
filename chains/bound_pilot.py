"""The pilot drives a bound robot after a chain run (docs/semantics.md §8, *The pilot*; §9, *Acting*; issue 26 item 5).

``skinet demo nav2`` plays its scenario through the chain, then hands a goals file to
the pilot (:func:`drive_goals`, the ``then`` of :func:`chains.chain.run_bound_chain`):
a pilot on the chain's session, with the default actuator (the bound skills' goals and
cancel requests on the simulated action servers), follows the monitor from where the
run left the robot and drives the mission in drive mode, asking the monitor's strict
check before every command.  The simulated robot's implementations
(:class:`services.simulator.world.World`) end every goal it accepts in its first success
mode, ``duration`` seconds later.

What it gives back (:class:`PilotEnd`) is read on the robot's side of the chain, not
taken from the pilot's word alone: what the actuator sent (the action client's own
log lines), the transitions the bridge reported meanwhile, and the properties the
monitor's verdicts showed violated; beside the pilot's last status.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import zenoh

from chains.chain import BoundChain, ChainError, wait_until
from services.common.zenoh_config import undeclare
from services.pilot import start_pilot
from services.pilot.act import Actuator, default_actuator
from chains.pilot_chain import ask_goal
from services.simulator.world import World
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import CanonicalEvent, PilotCommand, PilotGoalReply, PilotGoalRequest, PilotStatus, Verdicts

ENDED = ("reached", "failed", "cancelled")


@dataclass
class PilotEnd:
    """A mission the pilot drove, as the chain saw it."""

    reply: PilotGoalReply  # the pilot's answer to the mission
    status: PilotStatus  # its last status
    sent: list[str] = field(default_factory=list)  # what its actuator sent, in order
    transitions: list[str] = field(default_factory=list)  # 'skillset:transition' the bridge reported meanwhile
    violations: list[str] = field(default_factory=list)  # properties the monitor's verdicts showed violated


class _Logged:
    """An actuator that keeps what it sent."""

    def __init__(self, inner: Actuator):
        self.inner = inner
        self.sent: list[str] = []

    def send(self, command: PilotCommand) -> str:
        out = self.inner.send(command)
        self.sent.append(out)
        return out

    def close(self) -> None:
        self.inner.close()


class _Seen:
    """Events and verdicts of one system, as published."""

    def __init__(self, session: zenoh.Session, system: str):
        self.lock = threading.Lock()
        self.events: list[CanonicalEvent] = []
        self.violated: list[str] = []
        self.verdicts = -1  # seq of the last Verdicts seen
        self._seqs: dict[str, int] = {}  # skillset -> the highest seq of its events seen
        self._subs = [session.declare_subscriber(keys.events(system, "*"), self._on_event),
                      session.declare_subscriber(keys.verdicts(system), self._on_verdicts)]

    def last(self, skillset: str) -> int:
        """The highest seq of ``skillset``'s events seen (-1: none)."""
        with self.lock:
            return self._seqs.get(skillset, -1)

    def _on_event(self, sample: zenoh.Sample) -> None:
        event = decode(sample.payload.to_bytes(), CanonicalEvent)
        with self.lock:
            self.events.append(event)
            self._seqs[event.skillset] = max(self._seqs.get(event.skillset, -1), event.seq)

    def _on_verdicts(self, sample: zenoh.Sample) -> None:
        verdicts = decode(sample.payload.to_bytes(), Verdicts)
        with self.lock:
            self.verdicts = max(self.verdicts, verdicts.seq)
            self.violated += [v.name for v in verdicts.properties if not v.holds and v.name not in self.violated]

    def close(self) -> None:
        undeclare(*self._subs)


def drive_goals(chain: BoundChain, mission: str, mission_name: str, *, duration: float = 0.05,
                timeout: float = 60.0, settle: float = 10.0) -> PilotEnd:
    """Drive ``mission`` (a goals file's text, named ``mission_name`` in errors) with a pilot on ``chain``.

    Raises :class:`~chains.chain.ChainError` when the pilot refuses the mission, does not end it
    within ``timeout`` seconds, or the chain does not settle within ``settle``.
    """
    session, system = chain.session, chain.system
    world = World(chain.robot, duration=duration)  # each goal the robot accepts succeeds, ``duration`` s later
    seen = _Seen(session, system.name)
    actuator = _Logged(default_actuator(session, system, bindings=chain.bindings, style=chain.style))
    pilot = start_pilot(session, system, actuator=actuator)  # a random instance: one of its own per run
    try:
        wait_until(lambda: pilot.status.state == "idle", settle, "the pilot to follow the monitor")
        with seen.lock:
            first = len(seen.events)
        request = PilotGoalRequest(system=system.name, mission=mission, mission_name=mission_name, mode="drive")
        reply = ask_goal(session, request, settle)
        if not reply.accepted:
            raise ChainError(f"the pilot refused {mission_name}: {reply.reason}")
        wait_until(lambda: pilot.status.goal_id == reply.goal_id and pilot.status.state in ENDED, timeout,
              f"the end of {mission_name} (the pilot is {pilot.status.state})")
        status = pilot.status
        source = chain.bridge.feed.source
        wait_until(lambda: chain.bridge.wait_idle(settle) and all(
            (chain.monitor.last_seq(name, source) or 0) >= ss.seq - 1 for name, ss in chain.bridge.feed.skillsets.items()
            if ss.seq), settle, "the last events applied")
        wait_until(lambda: seen.verdicts >= chain.monitor.snapshot().verdicts.seq, settle, "the last verdicts")
        # The events come on a subscription of their own: a success may be heard here after the verdicts it caused.
        wait_until(lambda: all(seen.last(name) >= ss.seq - 1 for name, ss in chain.bridge.feed.skillsets.items()
                               if ss.seq), settle, "the last events seen")
        with seen.lock:
            transitions = [f"{e.skillset}:{e.transition}" for e in seen.events[first:] if e.transition]
            return PilotEnd(reply, status, list(actuator.sent), transitions, list(seen.violated))
    finally:
        pilot.close()
        seen.close()
        world.close()


__all__ = ["PilotEnd", "drive_goals"]
