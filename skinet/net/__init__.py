"""Petri nets of skillsets (docs/semantics.md §3): construction, firing, exports."""

from skinet.net.build import build_net, idle_place, resource_place, running_place
from skinet.net.petrinet import PetriNet, Transition
from skinet.net.semantics import enabled, fire, stabilize, stable_successors, steps

__all__ = [
    "PetriNet", "Transition", "build_net", "enabled", "fire", "idle_place",
    "resource_place", "running_place", "stabilize", "stable_successors", "steps",
]
