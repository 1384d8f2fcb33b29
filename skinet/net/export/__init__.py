"""Exports of a Petri net: JSON, Tina ``.net``, PNML, Graphviz and Promela (docs/semantics.md §3, *Interop*).

Every exporter is a pure function from a :class:`~skinet.net.petrinet.PetriNet`
to text; :data:`FORMATS` maps a format name to it (for the command line).
Every exporter raises :class:`DuplicateNameError` on a net whose place names
or transition ids are not unique.
"""

from __future__ import annotations

import json
from collections.abc import Callable

from skinet.net.export._common import DuplicateNameError, check_unique_names
from skinet.net.export.dot import to_dot
from skinet.net.export.netjson import JSON_FORMAT_VERSION, NetFormatError, from_json, to_json
from skinet.net.export.pnml import to_pnml
from skinet.net.export.promela import to_promela
from skinet.net.export.tina import to_tina
from skinet.net.petrinet import PetriNet


def to_json_text(net: PetriNet) -> str:
    """:func:`to_json` serialised with two-space indentation and a final newline."""
    return json.dumps(to_json(net), indent=2, ensure_ascii=False) + "\n"


FORMATS: dict[str, Callable[[PetriNet], str]] = {
    "json": to_json_text,
    "tina": to_tina,
    "pnml": to_pnml,
    "dot": to_dot,
    "promela": to_promela,
}

__all__ = [
    "FORMATS", "JSON_FORMAT_VERSION", "DuplicateNameError", "NetFormatError", "check_unique_names",
    "from_json", "to_dot", "to_json", "to_json_text", "to_pnml", "to_promela", "to_tina",
]
