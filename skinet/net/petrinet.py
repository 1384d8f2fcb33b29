"""Place/transition nets with unit arcs and a static priority relation (docs/semantics.md §3).

A net is compiled once into bit masks: a marking of a 1-safe net is a Python
``int`` whose bit ``i`` is set when place ``i`` holds a token, so enabledness
and firing are two mask operations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

Kind = Literal["event", "start", "invariant", "interrupt", "success", "failure"]
CONTROLLABLE_KINDS: frozenset[str] = frozenset({"start", "interrupt"})


@dataclass(frozen=True)
class Transition:
    """One transition variant.

    ``name`` is the logical name shown to users (``teleop.start``); ``id`` is
    unique in the net (``teleop.start#2`` for the second variant).  ``pre`` and
    ``post`` are place indices; a place in both is a test (self-loop).
    """

    id: str
    name: str
    kind: Kind
    pre: frozenset[int]
    post: frozenset[int]
    skillset: str
    skill: str | None = None  # the skill, for start/invariant/interrupt/modes
    element: str | None = None  # event, invariant or mode name
    commanded: bool = False  # an event someone commands (a binding's commanded resource, docs/semantics.md §9)
    pre_mask: int = field(default=0, compare=False, init=False)
    post_mask: int = field(default=0, compare=False, init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "pre_mask", sum(1 << i for i in self.pre))
        object.__setattr__(self, "post_mask", sum(1 << i for i in self.post))

    @property
    def controllable(self) -> bool:
        """Skill starts and interrupts are operator commands (docs/semantics.md §5), and so are commanded events (docs/semantics.md §9)."""
        return self.kind in CONTROLLABLE_KINDS or self.commanded

    @property
    def is_invariant(self) -> bool:
        return self.kind == "invariant"


@dataclass(frozen=True)
class PetriNet:
    """A 1-safe net; ``initial`` is the initial marking as a bit mask.

    ``priority`` lists pairs ``(high, low)`` of transition-index *groups*:
    every transition in ``high`` has priority over every one in ``low``.
    For skillset nets there is one pair per skillset: invariants over the rest.
    """

    name: str
    places: tuple[str, ...]
    transitions: tuple[Transition, ...]
    initial: int
    priority: tuple[tuple[frozenset[int], frozenset[int]], ...] = ()

    def place_index(self, name: str) -> int:
        return self._place_index[name]

    @property
    def _place_index(self) -> dict[str, int]:
        cache = self.__dict__.get("_pi")
        if cache is None:
            cache = {p: i for i, p in enumerate(self.places)}
            object.__setattr__(self, "_pi", cache)
        return cache

    def marked(self, marking: int) -> list[str]:
        """Names of the marked places, in place order."""
        return [p for i, p in enumerate(self.places) if marking >> i & 1]

    def marking_of(self, places: list[str] | set[str]) -> int:
        """The bit mask with exactly ``places`` marked."""
        m = 0
        for p in places:
            m |= 1 << self._place_index[p]
        return m

    @property
    def invariant_transitions(self) -> tuple[Transition, ...]:
        """The invariant transitions, computed once (hot in cascades)."""
        cache = self.__dict__.get("_inv")
        if cache is None:
            cache = tuple(t for t in self.transitions if t.is_invariant)
            object.__setattr__(self, "_inv", cache)
        return cache

    def transition_ids(self) -> list[str]:
        return [t.id for t in self.transitions]
