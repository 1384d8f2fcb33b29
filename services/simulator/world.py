"""The simulated robot's skill implementations: every started skill ends by itself (docs/pilot.md, *Try the pilot*).

A scenario plays each outcome as a step of its own (:mod:`services.simulator.driver`).
A pilot, or an operator with a GUI, has no such steps: it starts skills and waits for
their outcomes, as on the robot.  :class:`World` plays the implementations of a
simulated robot, the skillset managers of :class:`~services.simulator.service.Simulator`
or the action servers of :class:`~services.simulator.bound.BoundSimulator`: whenever a
request starts a skill, it ends that execution ``duration`` seconds later (a random time
in ``[0, duration]`` with ``rng``) in the mode that comes first of

- the next mode of ``script[(skillset, skill)]`` (tests: any mode, by name);
- what :class:`skinet.pilot.run.Outcomes` gives: the failure a pilot run declares for that
  run of that skill, else a failure mode drawn with the failure rate, else the skill's
  first success mode (the models give skills no duration, so one duration serves all).

A skill in ``holding`` is left running until :meth:`World.release`.  An execution that
stopped otherwise meanwhile (interrupted, an invariant failure, another goal) is left
alone.  :func:`simulated_robot` and :func:`self_ending` make the robot of ``python -m
services.simulator SYSTEM.toml --self-ending`` and ``skinet run SYSTEM.toml --simulate``.  One worker thread
ends the executions in the order they are due; cost O(log n) per start.
"""

from __future__ import annotations

import heapq
import logging
import random
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import zenoh

from skinet.pilot.run import Outcomes
from skinet.ros.keys import KeyStyle
from skinet.system.model import System

log = logging.getLogger("skinet.simulator")

SAMPLE_PERIOD = 1.0  # seconds between a bound robot's samples of its topics (a battery topic's usual rate)


class Robot(Protocol):
    """What the world needs of a simulated robot (:class:`~services.simulator.service.Simulator`,
    :class:`~services.simulator.bound.BoundSimulator`)."""

    system: System
    on_start: list[Callable[[str, str, str], None]]

    def terminate(self, skillset: str, skill: str, kind: str, mode: str = "", id_: str | None = None) -> bool: ...


@dataclass(frozen=True)
class End:
    """One execution as the world ended it (``ok`` false: it had stopped already)."""

    skillset: str
    skill: str
    id: str
    kind: str  # "success" | "failure"
    mode: str
    ok: bool

    def __str__(self) -> str:
        return f"{self.skillset}:{self.skill}.{self.kind}.{self.mode}" if self.mode else \
            f"{self.skillset}:{self.skill}.{self.kind}"


class World:
    """Ends the skills started on ``robot`` (the module docstring); :meth:`close` stops it (the robot stays).

    ``outcomes`` defaults to every run in its first success mode; ``script`` maps ``(skillset, skill)`` to
    the modes its next runs end in; ``holding`` lists ``(skillset, skill)`` left running until released.
    ``on_end`` callbacks hear of each :class:`End` (on the world's thread)."""

    def __init__(self, robot: Robot, outcomes: Outcomes | None = None, duration: float = 0.05, *,
                 script: Mapping[tuple[str, str], Sequence[str]] | None = None,
                 holding: Iterable[tuple[str, str]] = (), rng: random.Random | None = None):
        self.robot = robot
        self.outcomes = outcomes if outcomes is not None else Outcomes(robot.system)
        self.duration = duration
        self.script = {k: list(v) for k, v in (script or {}).items()}
        self.holding = set(holding)
        self.rng = rng
        self.ends: list[End] = []
        self.on_end: list[Callable[[End], None]] = []
        self._kinds = {(c.name, k.name): {m.name: m.kind for m in k.modes}
                       for c in robot.system.components for k in c.skillset.skills}
        self._due: list[tuple[float, int, str, str, str, str, str]] = []
        self._held: list[tuple[str, str, str, str, str]] = []
        self._count = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="skinet-world", daemon=True)
        self._thread.start()
        robot.on_start.append(self._started)

    @property
    def ended(self) -> list[str]:
        """``skillset:skill.kind.mode`` of every execution the world ended, in order."""
        with self._cond:
            return [str(e) for e in self.ends if e.ok]

    def _outcome(self, skillset: str, skill: str) -> tuple[str, str]:
        drawn = self.outcomes.outcome(skillset, skill)  # every start counts as a run, scripted or not
        queue = self.script.get((skillset, skill))
        if queue:
            mode = queue.pop(0)
            return self._kinds[(skillset, skill)][mode], mode
        return drawn

    def _started(self, skillset: str, skill: str, id_: str) -> None:
        """A request started ``skill`` (called under the robot's lock: only queues its end)."""
        with self._cond:
            kind, mode = self._outcome(skillset, skill)
            if (skillset, skill) in self.holding:
                self._held.append((skillset, skill, id_, kind, mode))
            else:
                self._due_now(skillset, skill, id_, kind, mode)

    def _due_now(self, skillset: str, skill: str, id_: str, kind: str, mode: str) -> None:
        wait = self.rng.uniform(0, self.duration) if self.rng is not None else self.duration
        self._count += 1
        heapq.heappush(self._due, (time.monotonic() + wait, self._count, skillset, skill, id_, kind, mode))
        self._cond.notify_all()

    def release(self, skillset: str, skill: str) -> None:
        """Stop holding ``skill``: the executions held end ``duration`` seconds from now, later ones as usual."""
        with self._cond:
            self.holding.discard((skillset, skill))
            held, self._held = self._held, []
            for entry in held:
                if entry[:2] == (skillset, skill):
                    self._due_now(*entry)
                else:
                    self._held.append(entry)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._closed and (not self._due or self._due[0][0] > time.monotonic()):
                    self._cond.wait(None if not self._due else self._due[0][0] - time.monotonic())
                if self._closed:
                    return
                _, _, skillset, skill, id_, kind, mode = heapq.heappop(self._due)
            try:
                ok = self.robot.terminate(skillset, skill, kind, mode, id_)
            except ValueError as exc:  # a bound skill whose result cannot name this mode: its default one
                log.warning("%s; %s:%s ends in its default %s mode instead", exc, skillset, skill, kind)
                mode = ""
                ok = self.robot.terminate(skillset, skill, kind, "", id_)
            if not ok:
                log.info("%s:%s (%s) had stopped before its %s %s", skillset, skill, id_, kind, mode)
            end = End(skillset, skill, id_, kind, mode, ok)
            with self._cond:
                self.ends.append(end)
                self._cond.notify_all()
            for callback in self.on_end:
                callback(end)

    def idle(self) -> bool:
        """Whether every execution started and not held has been ended (or found stopped)."""
        with self._cond:
            return not self._due and len(self.ends) == self._count

    def close(self) -> None:
        if self._started in self.robot.on_start:
            self.robot.on_start.remove(self._started)
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(5)


class SelfEnding:
    """A simulated robot whose skills end by themselves: the robot, its :class:`World` and, for bound
    skillsets, the periodic samples of their topics (:func:`self_ending`)."""

    def __init__(self, robot: Any, world: World, samples: Mapping[str, Mapping[str, Any]]):
        self.robot, self.world, self.samples = robot, world, samples
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if samples:
            self._thread = threading.Thread(target=self._publish, name="skinet-samples", daemon=True)
            self._thread.start()

    def _publish(self) -> None:
        """A bound robot's topics, published again every :data:`SAMPLE_PERIOD`: a bridge started later reads
        them too (they are volatile), and the values stay as they were."""
        while True:
            self.robot.publish_topics(self.samples)
            if self._stop.wait(SAMPLE_PERIOD):
                return

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        self.world.close()
        self.robot.close()


def simulated_robot(session: zenoh.Session, system: System, typemap: Mapping[str, str], bindings: Mapping[str, Any],
                    style: KeyStyle = KeyStyle()) -> Any:
    """The simulated robot of ``system`` on ``session``: its skillset managers
    (:class:`~services.simulator.service.Simulator`), or the bound interfaces of a system whose skillsets are all
    bound (``bindings``; :class:`~services.simulator.bound.BoundSimulator`).  ValueError for a system with both."""
    if bindings and len(bindings) != len(system.components):
        raise ValueError("the simulator plays systems of managers or of bindings, not both in one system yet")
    if bindings:
        from services.simulator.bound import BoundSimulator

        return BoundSimulator(session, system, bindings, style=style)
    from services.simulator.service import Simulator

    return Simulator(session, system, typemap, style=style)


def self_ending(robot: Any, outcomes: Outcomes | None = None, duration: float = 1.0) -> SelfEnding:
    """``robot``'s skills end by themselves, ``duration`` seconds after they start, as ``outcomes`` says; a bound
    robot (one with ``bindings``) publishes a first sample of each topic at once
    (:func:`skinet.ros.binding.first_samples`: the model's initial states), and again every second.  ValueError
    names a topic no such sample is found for (the robot is closed then)."""
    from skinet.ros.binding import first_samples

    samples: dict[str, Mapping[str, Any]] = {}
    try:
        for name, binding in getattr(robot, "bindings", {}).items():
            samples |= first_samples(binding, robot.system.component(name).skillset)
    except ValueError:
        robot.close()
        raise
    return SelfEnding(robot, World(robot, outcomes, duration), samples)


__all__ = ["End", "Robot", "SelfEnding", "World", "self_ending", "simulated_robot"]
