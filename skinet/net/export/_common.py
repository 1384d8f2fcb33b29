"""Checks shared by the exporters (docs/semantics.md §3, *Interop*)."""

from __future__ import annotations

from collections import Counter

from skinet.net.petrinet import PetriNet


class DuplicateNameError(ValueError):
    """Two places, or two transitions, of a net share a name.

    Text formats identify nodes by name (Tina merges repeated declarations), so
    a net with duplicates cannot be exported faithfully.
    """


def check_unique_names(net: PetriNet) -> None:
    """Raise :class:`DuplicateNameError` unless place names and transition ids are unique."""
    for what, names in (("place", net.places), ("transition id", net.transition_ids())):
        dups = sorted(n for n, c in Counter(names).items() if c > 1)
        if dups:
            raise DuplicateNameError(f"net {net.name!r}: duplicate {what}(s) {dups}")
