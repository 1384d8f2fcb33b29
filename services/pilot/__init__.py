"""The pilot service (docs/semantics.md §8, *The pilot*): goals in, safe skill requests out; see :mod:`services.pilot.service`."""

from services.pilot.errors import ActError
from services.pilot.act import Actuator, ManagerActuator, Routed, default_actuator, route
from services.pilot.service import Pilot, start_pilot

__all__ = ["ActError", "Actuator", "ManagerActuator", "Pilot", "Routed", "default_actuator", "route", "start_pilot"]
