"""Playing a mission scenario on the simulated managers (docs/mission.md, docs/semantics.md §7).

Each ``transition`` step of a scenario (:mod:`skinet.mission.scenario`) becomes, at time
``t / speed``, what would cause it on the real robot:

- ``k.start``: a ``Skill<K>Request`` on ``skill/<k>/request``, as an operator GUI sends it;
- ``k.interrupt``: a ``SkillInterrupt`` with the running id on ``skill/<k>/interrupt``;
- an event name: an ``EventRequest`` on ``event_request``;
- ``k.success.m`` / ``k.failure.m`` (``k.success`` for an unnamed mode): the simulated
  implementation terminates ``k`` in mode ``m``.

Requests travel over Zenoh; the driver waits until the manager has handled each one
before the next step.  ``consider`` steps do nothing on the robot; every step is then
reported to ``on_step`` (tests use it to look at the monitor at that moment).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol

import zenoh

from services.common.requests import Requests
from skinet.lang.model import Skillset
from skinet.mission.scenario import Scenario, Step, step_numbers
from skinet.ros.keys import KeyStyle, ManagerTopic
from skinet.ros.requests import event_request, skill_interrupt, skill_request
from skinet.system.model import Component

if TYPE_CHECKING:
    from skinet.ros.typestore import Typestore

log = logging.getLogger("skinet.simulator")

Action = Literal["start", "interrupt", "event", "success", "failure", "consider"]


class ManagerNode(Protocol):
    """One manager as the driver sees it: its skillset and its message types."""

    component: Component
    store: Typestore


class Managers(Protocol):
    """What the driver needs of the managers it drives (:class:`services.simulator.service.Simulator`
    is one; this module does not import it, so the dependency goes one way)."""

    session: zenoh.Session
    style: KeyStyle
    nodes: Mapping[str, ManagerNode]

    def handled(self, skillset: str, topic: str) -> int: ...

    def wait_handled(self, skillset: str, topic: str, count: int, timeout: float = 5.0) -> bool: ...

    def terminate(self, skillset: str, skill: str, kind: str, mode: str = "") -> bool: ...

    def skill_status(self, skillset: str, skill: str) -> tuple[bool, str]: ...


@dataclass(frozen=True)
class Planned:
    """What the driver does for one step."""

    action: Action
    skill: str | None = None
    name: str = ""  # event name or mode name


@dataclass(frozen=True)
class StepRun:
    """One step as played: ``ok`` is false when the robot did not do it (e.g. skill not running)."""

    index: int  # the step number of :func:`skinet.mission.scenario.step_numbers`, as in :class:`skinet.mission.scenario.StepRecord`
    step: Step
    action: Action
    ok: bool
    detail: str = ""  # the request id, or why the step did nothing


def plan(skillset: Skillset, step: Step) -> Planned:
    """The driver's action for ``step``; ``ValueError`` on a name the skillset lacks."""
    if step.consider is not None:
        return Planned("consider")
    name = step.transition or ""
    if name in {e.name for e in skillset.events}:
        return Planned("event", name=name)
    skills = {k.name: k for k in skillset.skills}
    head, _, rest = name.partition(".")
    if head not in skills:
        raise ValueError(f"'{name}' is neither an event nor a skill transition of '{skillset.name}'")
    kind, _, mode = rest.partition(".")
    if rest in ("start", "interrupt"):
        return Planned(rest, head)  # type: ignore[arg-type]
    if kind in ("success", "failure") and any(m.kind == kind and m.name == mode for m in skills[head].modes):
        return Planned(kind, head, mode)  # type: ignore[arg-type]
    raise ValueError(f"'{name}' cannot be driven on '{skillset.name}' (use k.start, k.interrupt, "
                     f"k.success.m, k.failure.m or an event; invariant failures follow from resource changes)")


class Operator:
    """Sends requests to the managers over Zenoh, like an operator GUI (:mod:`skinet.ros.requests`)."""

    def __init__(self, session: zenoh.Session, simulator: Managers):
        self.simulator = simulator
        self._requests = Requests(session, ((n.component, n.store) for n in simulator.nodes.values()),
                                  simulator.style, b"operator-gui-gid")

    def send(self, skillset: str, request: tuple[ManagerTopic, bytes], timeout: float = 5.0) -> bool:
        """Publish one request (:func:`skinet.ros.requests.skill_request`...) and wait until the manager
        has handled it."""
        topic, payload = request
        before = self.simulator.handled(skillset, topic.topic)
        self._requests.put(skillset, topic, payload)
        return self.simulator.wait_handled(skillset, topic.topic, before + 1, timeout)

    def close(self) -> None:
        self._requests.close()


def drive(simulator: Managers, scenario: Scenario, speed: float = 1.0,
          on_step: Callable[[StepRun], None] | None = None) -> list[StepRun]:
    """Play ``scenario`` on ``simulator`` (``speed`` <= 0 or ``inf``: as fast as possible).

    Raises ``ValueError`` before anything is sent when a step names something the
    system lacks.
    """
    plans = []
    for i, step in enumerate(scenario.steps, 1):
        if step.skillset not in simulator.nodes:
            raise ValueError(f"step {i}: unknown skillset '{step.skillset}' (skillsets: {', '.join(simulator.nodes)})")
        try:
            plans.append(plan(simulator.nodes[step.skillset].component.skillset, step))
        except ValueError as exc:
            raise ValueError(f"step {i}: {exc}") from None
    operator = Operator(simulator.session, simulator)
    runs: list[StepRun] = []
    origin = time.monotonic()
    try:
        for i, step, p in zip(step_numbers(scenario), scenario.steps, plans):
            if speed > 0 and not math.isinf(speed):
                delay = origin + step.t / speed - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            node = simulator.nodes[step.skillset]
            ss, store = node.component.skillset, node.store
            ok, detail = True, ""
            if p.action == "start":
                detail = f"{scenario.name}-{i}"
                ok = operator.send(step.skillset, skill_request(store, ss, p.skill or "", detail))
                ok = ok and simulator.skill_status(step.skillset, p.skill or "") == (True, detail)
                detail = detail if ok else f"the manager did not start {p.skill} (request '{detail}')"
            elif p.action == "interrupt":
                running, detail = simulator.skill_status(step.skillset, p.skill or "")
                ok = operator.send(step.skillset, skill_interrupt(store, ss, p.skill or "", detail))
                ok = ok and running
            elif p.action == "event":
                detail = f"{scenario.name}-{i}"
                ok = operator.send(step.skillset, event_request(store, ss, detail, p.name))
            elif p.action in ("success", "failure"):
                ok = simulator.terminate(step.skillset, p.skill or "", p.action, p.name)
                detail = "" if ok else f"{p.skill} is not running"
            run = StepRun(i, step, p.action, ok, detail)
            if not ok:
                log.warning("step %d (%s:%s) had no effect: %s", i, step.skillset, step.transition, detail or "timeout")
            runs.append(run)
            if on_step is not None:
                on_step(run)
    finally:
        operator.close()
    return runs


__all__ = ["Managers", "Operator", "Planned", "StepRun", "drive", "plan"]
