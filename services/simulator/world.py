"""The simulated skills' implementations: every started skill ends by itself (issue 24, the demo's pilot run).

A scenario plays each outcome as a step of its own (:mod:`services.simulator.driver`).
A pilot run has no such steps: the pilot starts skills and waits for their outcomes,
as on the robot.  :class:`World` plays the implementations: whenever a request starts
a skill on the simulated managers, it ends that execution ``duration`` seconds later in
the mode :class:`skinet.pilot.run.Outcomes` gives (the favourable success mode, or the
failure a pilot run declares for that run of that skill).  An execution that stopped
otherwise meanwhile (interrupted, an invariant failure) is left alone.  One worker thread
ends them in the order they are due; cost O(log n) per start.
"""

from __future__ import annotations

import heapq
import logging
import threading
import time
from dataclasses import dataclass

from services.simulator.service import Simulator
from skinet.pilot.run import Outcomes

log = logging.getLogger("skinet.simulator")


@dataclass(frozen=True)
class End:
    """One execution as the world ended it (``ok`` false: it had stopped already)."""

    skillset: str
    skill: str
    id: str
    kind: str  # "success" | "failure"
    mode: str
    ok: bool


class World:
    """Ends the skills started on ``simulator``; :meth:`close` stops it (the simulator stays)."""

    def __init__(self, simulator: Simulator, outcomes: Outcomes, duration: float = 0.0):
        self.simulator = simulator
        self.outcomes = outcomes
        self.duration = duration
        self.ends: list[End] = []
        self._due: list[tuple[float, int, str, str, str, str, str]] = []
        self._count = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="skinet-world", daemon=True)
        self._thread.start()
        simulator.on_start.append(self._started)

    def _started(self, skillset: str, skill: str, id_: str) -> None:
        kind, mode = self.outcomes.outcome(skillset, skill)
        with self._cond:
            self._count += 1
            heapq.heappush(self._due, (time.monotonic() + self.duration, self._count, skillset, skill, id_, kind, mode))
            self._cond.notify_all()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._closed and (not self._due or self._due[0][0] > time.monotonic()):
                    self._cond.wait(None if not self._due else self._due[0][0] - time.monotonic())
                if self._closed:
                    return
                _, _, skillset, skill, id_, kind, mode = heapq.heappop(self._due)
            ok = self.simulator.terminate(skillset, skill, kind, mode, id_)
            if not ok:
                log.info("%s:%s (%s) had stopped before its %s %s", skillset, skill, id_, kind, mode)
            with self._cond:
                self.ends.append(End(skillset, skill, id_, kind, mode, ok))
                self._cond.notify_all()

    def idle(self) -> bool:
        """Whether every started execution has been ended (or found stopped)."""
        with self._cond:
            return not self._due and len(self.ends) == self._count

    def close(self) -> None:
        if self._started in self.simulator.on_start:
            self.simulator.on_start.remove(self._started)
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(5)


__all__ = ["End", "World"]
