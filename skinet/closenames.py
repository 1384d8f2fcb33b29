"""Unknown names told with the known ones closest to them (system, scenario and goal files, settings).

A typo in a key must never be ignored: a system file whose ``propertis`` is
skipped supervises nothing.  Every reader that refuses an unknown name words
it the same way, ``unknown key 'propertis' in [system] (candidates: properties)``:
the close names when there are some (``difflib``'s ratio >= 0.6), else every
known name.  Pure; cost O(known names x name length^2).

Examples:
    >>> unknown("key", "propertis", ["name", "properties", "types"], " in [system]")
    "unknown key 'propertis' in [system] (candidates: properties)"
    >>> unknown("table", "[zzz]", ["[system]", "[[skillsets]]"])
    "unknown table '[zzz]' (expected one of: [system], [[skillsets]])"
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence

MAX_CANDIDATES = 6


def close_names(name: str, known: Sequence[str], cutoff: float = 0.6) -> list[str]:
    """The names of ``known`` close to ``name`` (similarity ratio >= ``cutoff``), closest first
    (at most :data:`MAX_CANDIDATES`)."""
    return difflib.get_close_matches(name, list(known), n=MAX_CANDIDATES, cutoff=cutoff)


def unknown(what: str, name: str, known: Sequence[str], where: str = "") -> str:
    """``unknown WHAT 'NAME'WHERE (candidates: ...)``, or every known name when none is close."""
    close = close_names(name, known)
    if close:
        return f"unknown {what} '{name}'{where} (candidates: {', '.join(close)})"
    return f"unknown {what} '{name}'{where} (expected one of: {', '.join(known) or 'none'})"
