"""A robot the pilot can drive, through a real router: what ``skinet goal`` and the dashboard's goal box talk to.

:class:`PilotedRobot` runs, each on a client session of the router as a deployment would:
the simulated managers and the bridge (the robot), the monitor, a predictor and the real
pilot (:func:`services.pilot.start_pilot`).  :class:`World` plays the skills' implementations:
a skill that starts ends a moment later in the outcome its script gives (default: its first
success mode), so a goal in drive mode runs to its end with nobody else acting.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable
from types import TracebackType

import zenoh

from services.bridge_ros2 import start_bridge
from services.monitor import start_monitor
from services.predictor.service import start_predictor
from services.simulator.service import Simulator
from skinet.files import load_system, load_typemap
from tests.services.conftest import REPO, open_client

SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"


class World:
    """Ends every skill that runs after ``delay`` seconds, in the outcome its script gives.

    ``script[(skillset, skill)]`` lists outcomes (``"success.MODE"`` or ``"failure.MODE"``)
    used one per execution; past the list (or without one) a skill ends in its first
    success mode.  ``always[(skillset, skill)]`` is used for every execution.  ``hold``
    lists skills left running (a manager that never reports)."""

    def __init__(self, sim: Simulator, delay: float = 0.3, script: dict[tuple[str, str], list[str]] | None = None,
                 always: dict[tuple[str, str], str] | None = None, hold: Iterable[tuple[str, str]] = ()):
        self.sim, self.delay = sim, delay
        self.script = {k: list(v) for k, v in (script or {}).items()}
        self.always = dict(always or {})
        self.hold = set(hold)
        self.ended: list[tuple[str, str, str]] = []  # (skillset, skill, outcome), in order
        self._seen: dict[tuple[str, str], tuple[str, float]] = {}  # running skill -> (execution id, first seen)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="test-world", daemon=True)
        self._thread.start()

    def _outcome(self, key: tuple[str, str]) -> str:
        if key in self.always:
            return self.always[key]
        if self.script.get(key):
            return self.script[key].pop(0)
        skill = self.sim.nodes[key[0]].component.skillset.skill(key[1])
        return f"success.{skill.successes[0].name}"

    def _run(self) -> None:
        while not self._stop.wait(0.02):
            for name, node in self.sim.nodes.items():
                for skill in node.component.skillset.skills:
                    key = (name, skill.name)
                    running, execution = self.sim.skill_status(*key)
                    if not running or key in self.hold:
                        self._seen.pop(key, None)
                        continue
                    seen = self._seen.setdefault(key, (execution, time.monotonic()))
                    if seen[0] != execution:
                        self._seen[key] = seen = (execution, time.monotonic())
                    if time.monotonic() - seen[1] >= self.delay:
                        outcome = self._outcome(key)
                        kind, _, mode = outcome.partition(".")
                        if self.sim.terminate(name, skill.name, kind, mode):
                            self.ended.append((name, skill.name, outcome))
                        self._seen.pop(key, None)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)


class PilotedRobot:
    """The paper's system on simulated managers, watched and driven through ``router`` (close it, or use ``with``)."""

    def __init__(self, router: str, world: dict | None = None, **pilot_options: object):
        from services.pilot import start_pilot

        self.system, _ = load_system(SYSTEM_FILE)
        self.typemap = load_typemap(SYSTEM_FILE)
        self.sessions: list[zenoh.Session] = []
        self._services: list[object] = []
        robot, services = self._open(router), self._open(router)
        self.sim = self._add(Simulator(robot, self.system, self.typemap))
        self._add(start_bridge(robot, self.system, self.typemap))
        self.monitor = self._add(start_monitor(services, self.system))
        self._add(start_predictor(services, "test-predictor"))
        self.world = self._add(World(self.sim, **(world or {})))
        self.pilot = self._add(start_pilot(services, self.system, instance="test-pilot", **pilot_options))
        deadline = time.monotonic() + 20
        while not (self.monitor.synced() and not self.monitor.snapshot().unsafe.prediction_stale):
            if time.monotonic() > deadline:
                raise TimeoutError("the monitor never showed a live state with a fresh prediction")
            time.sleep(0.05)

    def _open(self, router: str) -> zenoh.Session:
        self.sessions.append(open_client(router))
        return self.sessions[-1]

    def _add(self, service):  # type: ignore[no-untyped-def]
        self._services.append(service)
        return service

    def close(self) -> None:
        for service in reversed(self._services):
            service.close()  # type: ignore[attr-defined]
        for session in reversed(self.sessions):
            session.close()

    def __enter__(self) -> PilotedRobot:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()
