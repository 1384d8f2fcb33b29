"""The paper's robot for pilot tests, through a real router (docs/semantics.md §8; issue 24).

:class:`Robot` runs the simulated managers (real CDR on bridge keys), the bridge,
the monitor and a predictor, each on its own client session of the test's router,
and a pilot on another; the robot's side of the skills is
:class:`services.simulator.world.World` (each execution ends in the mode a script or
the outcomes give, after a delay; the managers then speak the real protocol).  :class:`Recording` wraps the
pilot's real actuator (:func:`~services.pilot.act.default_actuator`) and keeps what it sent, in order.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import pytest
import zenoh

from services.bridge_ros2 import start_bridge
from services.common.goals import pilot_status
from services.common.requests import Requests
from services.monitor import start_monitor
from services.pilot import Actuator, Pilot, default_actuator, start_pilot
from services.pilot.act import inputs_problem
from services.predictor.service import start_predictor
from services.simulator import Simulator
from skinet.ros.keys import KeyStyle
from skinet.ros.requests import skill_interrupt, skill_request
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import PilotCommand, PilotGoalReply, PilotGoalRequest, PilotStatus
from tests.event_watch import Messages

WALK = {"go_to_waypoint": {"target": {"x": 12.0, "y": 3.5, "z": 0.0}}}
LAST_REPLY: list[PilotGoalReply] = []  # the last reply ask_goal received in this process, for a timeout's diagnosis


class Recording:
    """The pilot's actuator, keeping every command it sent (``skillset:transition``)."""

    def __init__(self, inner: Actuator):
        self.inner = inner
        self.sent: list[str] = []
        self.inputs: list[dict[str, Any]] = []
        self.asked: list[str] = []  # skillsets whose manager was asked for its status

    def send(self, command: PilotCommand) -> str:
        out = self.inner.send(command)
        self.sent.append(f"{command.skillset}:{command.transition}")
        self.inputs.append(command.inputs)
        return out

    def problem(self, skillset: str, skill: str, inputs: dict[str, Any]) -> str | None:
        return inputs_problem(self.inner, skillset, skill, inputs)

    def start_inputs(self, skillset: str, skill: str, given: dict[str, Any]) -> Any:
        return self.inner.start_inputs(skillset, skill, given)  # type: ignore[attr-defined]

    def ask_status(self, skillset: str) -> str:
        self.asked.append(skillset)
        return self.inner.ask_status(skillset)  # type: ignore[attr-defined]

    def close(self) -> None:
        self.inner.close()


class Statuses(Messages[PilotStatus]):
    """Every PilotStatus published, in arrival order, with a blocking wait."""

    def __init__(self, session: zenoh.Session, system: str = "spot_arm"):
        super().__init__(session, keys.pilot_status(system), PilotStatus)
        self.session, self.system = session, system

    def first(self, predicate: Callable[[PilotStatus], bool], timeout: float = 60.0, what: str = "") -> PilotStatus:
        """The first status (from now on or already received) for which ``predicate`` holds.  On a
        timeout it says the last status received and the one the pilot's queryable answers: a run of
        session 18's received none at all while the publisher had matched the subscriber."""
        try:
            items = super().wait(lambda items: any(predicate(s) for s in items), timeout)
        except AssertionError:
            last = self.items[-1] if self.items else None
            reply = LAST_REPLY[0] if LAST_REPLY else None
            pytest.fail(f"no pilot status {what} within {timeout} s; {len(self.items)} received, last: "
                        f"{None if last is None else (last.state, last.reason, last.next)}; the pilot's "
                        f"queryable answers {self._asked()}; the last goal reply: "
                        f"{None if reply is None else (reply.accepted, reply.goal_id, reply.reason)}")
        return next(s for s in items if predicate(s))

    def _asked(self) -> object:
        """The pilot's status as its queryable answers it now: (state, reason, next), or why there is none."""
        try:
            s = pilot_status(self.session, self.system, timeout=5.0)
        except Exception as exc:  # a diagnosis only: the failure it explains is raised anyway
            return f"no answer ({exc})"
        return "no answer" if s is None else (s.state, s.reason, s.next)

    def state(self, state: str, goal: int | None = None, timeout: float = 60.0) -> PilotStatus:
        return self.first(lambda s: s.state == state and (goal is None or s.goal_id == goal), timeout,
                          f"'{state}'")

    def states(self, goal: int) -> list[str]:
        """The states of ``goal``'s statuses, repeats dropped."""
        with self._cond:
            out: list[str] = []
            for s in self.items:
                if s.goal_id == goal and (not out or out[-1] != s.state):
                    out.append(s.state)
            return out


def matched_statuses(observer: zenoh.Session, pilot: Pilot, system: str = "spot_arm") -> Statuses:
    """A subscriber of ``pilot``'s statuses on ``observer``, once the pilot's publisher knows of it: a client's
    publisher sends only where the router said a subscriber is, so a status published before is never received
    (a run beside busy loops on both cores once saw no status at all in 60 s; a full run, the Nav2 rig's first
    'idle').  Declared again if not matched within 10 s.  Wait for what the pilot was before with
    :func:`wait_pilot`."""
    for _ in range(3):
        statuses = Statuses(observer, system)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            if pilot._pub.matching_status.matching:
                return statuses
            time.sleep(0.05)
        statuses._sub.undeclare()
    pytest.fail("the pilot's status publisher never matched the test's subscriber (3 tries of 10 s)")


def wait_pilot(pilot: Pilot, state: str, timeout: float = 30.0) -> None:
    """Until ``pilot``'s own last status is ``state``."""
    deadline = time.monotonic() + timeout
    while pilot.status.state != state:
        if time.monotonic() > deadline:
            pytest.fail(f"the pilot is {pilot.status.state} ({pilot.status.reason}), not {state}")
        time.sleep(0.01)


def ask_goal(session: zenoh.Session, request: PilotGoalRequest | bytes | None, client: str = "operator1",
             system: str = "spot_arm") -> PilotGoalReply:
    """One goal request on the pilot's queryable, as ``client``."""
    payload = request if isinstance(request, (bytes, type(None))) else encode(request)
    replies = list(session.get(keys.pilot_goal(system, client), payload=payload, timeout=10.0))
    assert len(replies) == 1 and replies[0].ok is not None, replies
    LAST_REPLY[:] = [decode(replies[0].ok.payload.to_bytes(), PilotGoalReply)]
    return LAST_REPLY[0]


def goal(*goals: str, **fields: Any) -> PilotGoalRequest:
    return PilotGoalRequest(system=fields.pop("system", "spot_arm"), goals=list(goals), **fields)


class Robot:
    """Simulator, bridge, monitor, predictor and pilot of the paper's system, each on its own client session."""

    def __init__(self, sessions: Callable[[], zenoh.Session], system: System, typemap: dict[str, str],
                 monitor: bool = True, style: KeyStyle = KeyStyle(), lost_after: float = 2.0,
                 pilot_system: System | None = None, **pilot: Any):
        self.system, self.typemap, self.sessions, self.lost_after = system, typemap, sessions, lost_after
        self.sim = Simulator(sessions(), system, typemap, style=style)
        self.bridge = start_bridge(sessions(), system, typemap, style=style)
        self.predictor: Any = start_predictor(sessions(), "pilot-test", workers=1)
        self.monitor: Any = None
        if monitor:
            self.start_monitor()
        pilot_session = sessions()
        self.actuator = Recording(default_actuator(pilot_session, system, typemap, style, instance="p1"))
        # The planner's memory limit is the whole process's: here that is a test worker holding every test before
        # (a full run's worker went past 1 GiB, and the pilot answered a goal 'unknown' on memory).
        pilot.setdefault("memory_limit", None)
        self.pilot: Pilot = start_pilot(pilot_session, pilot_system or system, instance="p1",
                                        actuator=pilot.pop("actuator", self.actuator), typemap=typemap, **pilot)
        self.observer = sessions()
        self.statuses = matched_statuses(self.observer, self.pilot)
        if monitor:
            self.wait_synced()
            self.wait_pilot("idle")

    def wait_pilot(self, state: str, timeout: float = 30.0) -> None:
        wait_pilot(self.pilot, state, timeout)

    def wait_pilot_step(self, timeout: float = 30.0) -> None:
        """Until the pilot's own status is about the monitor's last step: a goal asked before may be planned from
        an older one (the pilot hears the monitor's states through Zenoh; a run beside busy loops once saw a goal
        planned from the step before the one the test had waited for)."""
        deadline = time.monotonic() + timeout
        while self.pilot.status.state_seq < self.monitor.snapshot().state.seq:
            if time.monotonic() > deadline:
                pytest.fail(f"the pilot's status is about step {self.pilot.status.state_seq}, the monitor's last "
                            f"is {self.monitor.snapshot().state.seq}")
            time.sleep(0.01)

    def start_monitor(self) -> None:
        self.monitor = start_monitor(self.sessions(), self.system, lost_after=self.lost_after)

    def wait_synced(self, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while self.monitor is None or not self.monitor.synced():
            if time.monotonic() > deadline:
                pytest.fail("the monitor did not sync")
            time.sleep(0.01)

    def close(self) -> None:
        self.pilot.close()
        if self.monitor is not None:
            self.monitor.close()
        self.bridge.close()
        self.sim.close()
        if self.predictor is not None:
            self.predictor.close()


class Gui:
    """An operator's GUI: its own requests to the managers (the same protocol as the pilot's)."""

    def __init__(self, session: zenoh.Session, robot: Robot):
        self.robot = robot
        self.stores = {name: node.store for name, node in robot.sim.nodes.items()}
        self.requests = Requests(session, [(n.component, n.store) for n in robot.sim.nodes.values()])
        self.count = 0

    def start(self, skillset: str, skill: str, inputs: dict[str, Any] | None = None) -> None:
        self.count += 1
        component = self.robot.system.component(skillset)
        self.requests.put(skillset, *skill_request(self.stores[skillset], component.skillset, skill,
                                                   f"gui-{self.count}", inputs))

    def interrupt(self, skillset: str, skill: str) -> None:
        """Interrupt ``skill`` with the running id its manager's status shows."""
        _, id_ = self.robot.sim.skill_status(skillset, skill)
        component = self.robot.system.component(skillset)
        self.requests.put(skillset, *skill_interrupt(self.stores[skillset], component.skillset, skill, id_))

    def close(self) -> None:
        self.requests.close()
