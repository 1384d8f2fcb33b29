"""Disjoint union of skillset nets (docs/semantics.md §3, *Eventless net*).

Names are prefixed with ``skillset:`` so places and transitions of different
components never collide; each component keeps its own priority pair.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from skinet.net.petrinet import PetriNet


def union(nets: Sequence[PetriNet], name: str = "union") -> PetriNet:
    """The disjoint union of ``nets`` (markings concatenate bit ranges in order)."""
    places: list[str] = []
    transitions = []
    priority = []
    initial = 0
    t_offset = 0
    for net in nets:
        p_offset = len(places)
        prefix = f"{net.name.removesuffix('_eventless')}:"
        places.extend(prefix + p for p in net.places)
        initial |= net.initial << p_offset
        for t in net.transitions:
            transitions.append(
                replace(
                    t,
                    id=prefix + t.id,
                    pre=frozenset(i + p_offset for i in t.pre),
                    post=frozenset(i + p_offset for i in t.post),
                )
            )
        for high, low in net.priority:
            priority.append((frozenset(i + t_offset for i in high), frozenset(i + t_offset for i in low)))
        t_offset += len(net.transitions)
    return PetriNet(name, tuple(places), tuple(transitions), initial, tuple(priority))
