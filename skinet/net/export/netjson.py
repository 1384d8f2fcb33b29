"""A JSON form of a net, and back (docs/semantics.md §3, *Interop*).

:func:`to_json` gives a plain ``dict`` (ready for :func:`json.dumps`) that names
places and transitions instead of indexing them::

    {
      "format_version": 1,
      "name": "spot",
      "places": ["power.Off", ...],              # in index order
      "initial": ["power.Off", "e_move"],        # marked places, in place order
      "transitions": [
        {"id": "move.start", "name": "move.start", "kind": "start",
         "skillset": "spot", "skill": "move", "element": null,
         "controllable": true,
         "pre": ["power.On", "e_move"], "post": ["power.On", "i_move"]},
        ...
      ],
      "priority": [{"high": ["move.inv.x"], "low": ["ev", "move.start", ...]}]
    }

A place in both ``pre`` and ``post`` is a test.  ``controllable`` is derived
from ``kind`` (an event is controllable when its binding says it is commanded,
docs/semantics.md §9); on input it only marks an event as commanded.  :func:`from_json` rebuilds an equal
:class:`~skinet.net.petrinet.PetriNet` with compiled bit masks.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast, get_args

from skinet.errors import SkinetError
from skinet.net.export._common import check_unique_names
from skinet.net.petrinet import Kind, PetriNet, Transition

JSON_FORMAT_VERSION = 1
_KINDS: frozenset[str] = frozenset(get_args(Kind))


class NetFormatError(SkinetError, ValueError):
    """A JSON net that :func:`from_json` cannot read."""


def to_json(net: PetriNet) -> dict[str, Any]:
    """``net`` as a JSON-ready ``dict`` (layout in the module docstring)."""
    check_unique_names(net)
    places = net.places
    ids = net.transition_ids()
    return {
        "format_version": JSON_FORMAT_VERSION,
        "name": net.name,
        "places": list(places),
        "initial": net.marked(net.initial),
        "transitions": [
            {
                "id": t.id,
                "name": t.name,
                "kind": t.kind,
                "skillset": t.skillset,
                "skill": t.skill,
                "element": t.element,
                "controllable": t.controllable,
                "pre": [places[i] for i in sorted(t.pre)],
                "post": [places[i] for i in sorted(t.post)],
            }
            for t in net.transitions
        ],
        "priority": [
            {"high": [ids[j] for j in sorted(high)], "low": [ids[j] for j in sorted(low)]}
            for high, low in net.priority
        ],
    }


def _lookup(index: Mapping[str, int], names: Iterable[str], what: str, where: str) -> frozenset[int]:
    out: set[int] = set()
    for name in names:
        if name not in index:
            raise NetFormatError(f"{where}: unknown {what} {name!r}")
        out.add(index[name])
    return frozenset(out)


def _unique(names: Sequence[str], what: str) -> dict[str, int]:
    index: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in index:
            raise NetFormatError(f"duplicate {what} {name!r}")
        index[name] = i
    return index


def from_json(data: Mapping[str, Any]) -> PetriNet:
    """The net described by ``data`` (as produced by :func:`to_json`).

    Raises:
        NetFormatError: on a missing key, another ``format_version``, a
            duplicate name or a reference to an unknown place or transition.
    """
    version = data.get("format_version")
    if version != JSON_FORMAT_VERSION:
        raise NetFormatError(f"format_version {version!r} is not {JSON_FORMAT_VERSION}")
    try:
        places = tuple(str(p) for p in data["places"])
        place_index = _unique(places, "place")
        transitions = []
        for t in data["transitions"]:
            tid = str(t["id"])
            if t["kind"] not in _KINDS:
                raise NetFormatError(f"transition {tid!r}: unknown kind {t['kind']!r}")
            transitions.append(
                Transition(
                    id=tid,
                    name=str(t["name"]),
                    kind=cast(Kind, t["kind"]),
                    pre=_lookup(place_index, t["pre"], "place", f"transition {tid!r}"),
                    post=_lookup(place_index, t["post"], "place", f"transition {tid!r}"),
                    skillset=str(t["skillset"]),
                    skill=t.get("skill"),
                    element=t.get("element"),
                    commanded=t["kind"] == "event" and t.get("controllable") is True,
                )
            )
        tr_index = _unique([t.id for t in transitions], "transition id")
        initial = sum(1 << i for i in _lookup(place_index, data["initial"], "place", "initial"))
        priority = tuple(
            (
                _lookup(tr_index, pair["high"], "transition", "priority"),
                _lookup(tr_index, pair["low"], "transition", "priority"),
            )
            for pair in data.get("priority", [])
        )
        return PetriNet(str(data["name"]), places, tuple(transitions), initial, priority)
    except (KeyError, TypeError) as exc:
        raise NetFormatError(f"malformed JSON net: {exc!r}") from exc
