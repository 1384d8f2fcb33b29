"""Simulated skillset managers driven by mission scenarios (docs/semantics.md §7, docs/mission.md).

``Simulator(session, system, typemap)`` serves every manager of a system on Zenoh;
``Simulator.drive(scenario, speed, on_step)`` plays a scenario on it.
"""

from services.simulator.driver import StepRun, drive
from services.simulator.manager import Manager
from services.simulator.service import Simulator

__all__ = ["Manager", "Simulator", "StepRun", "drive"]
