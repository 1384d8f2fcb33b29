"""Export to PNML, the ISO/IEC 15909-2 P/T net format (docs/semantics.md §3, *Interop*).

The document is a P/T net (``type`` = :data:`PTNET_TYPE`) on one page.  XML ids
must be NCNames, which our names are not (``k.start#2``), so elements get the
ids ``p<i>``, ``t<i>`` and ``a<i>`` (in net order) and the real name goes in
``<name><text>``.  A transition's name is its unique id; its logical name and
kind go in a per-transition ``toolspecific`` element.  A place is marked with
``<initialMarking><text>1</text></initialMarking>``; unmarked places omit it
(the PNML default is 0).  A test (a place in both ``pre`` and ``post``) is two
arcs, place -> transition and transition -> place.

Priorities are not part of standard PNML, so each priority pair of the net is
listed in a net-level ``<toolspecific tool="skinet" version="1">``::

    <priority>
      <high><transition idref="t2"/>...</high>
      <low><transition idref="t0"/>...</low>
    </priority>

meaning every transition of ``high`` has priority over every one of ``low``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from skinet.net.export._common import check_unique_names
from skinet.net.petrinet import PetriNet

PNML_NS = "http://www.pnml.org/version-2009/grammar/pnml"
PTNET_TYPE = "http://www.pnml.org/version-2009/grammar/ptnet"
TOOL = "skinet"
TOOL_VERSION = "1"


def _text(parent: ET.Element, tag: str, text: str) -> ET.Element:
    """``<tag><text>text</text></tag>`` under ``parent``."""
    element = ET.SubElement(parent, tag)
    ET.SubElement(element, "text").text = text
    return element


def _toolspecific(parent: ET.Element) -> ET.Element:
    return ET.SubElement(parent, "toolspecific", {"tool": TOOL, "version": TOOL_VERSION})


def to_pnml_tree(net: PetriNet) -> ET.Element:
    """The ``<pnml>`` element of ``net`` (see the module docstring for the layout)."""
    check_unique_names(net)
    root = ET.Element("pnml", {"xmlns": PNML_NS})
    net_el = ET.SubElement(root, "net", {"id": "net", "type": PTNET_TYPE})
    _text(net_el, "name", net.name)
    page = ET.SubElement(net_el, "page", {"id": "page"})
    for i, place in enumerate(net.places):
        place_el = ET.SubElement(page, "place", {"id": f"p{i}"})
        _text(place_el, "name", place)
        if net.initial >> i & 1:
            _text(place_el, "initialMarking", "1")
    for j, t in enumerate(net.transitions):
        tr_el = ET.SubElement(page, "transition", {"id": f"t{j}"})
        _text(tr_el, "name", t.id)
        info = {"name": t.name, "kind": t.kind, "skillset": t.skillset}
        if t.skill is not None:
            info["skill"] = t.skill
        if t.element is not None:
            info["element"] = t.element
        ET.SubElement(_toolspecific(tr_el), "transition", info)
    arc = 0
    for j, t in enumerate(net.transitions):
        for i in sorted(t.pre):
            ET.SubElement(page, "arc", {"id": f"a{arc}", "source": f"p{i}", "target": f"t{j}"})
            arc += 1
        for i in sorted(t.post):
            ET.SubElement(page, "arc", {"id": f"a{arc}", "source": f"t{j}", "target": f"p{i}"})
            arc += 1
    if net.priority:
        tool = _toolspecific(net_el)
        for high, low in net.priority:
            pair = ET.SubElement(tool, "priority")
            for side, group in (("high", high), ("low", low)):
                side_el = ET.SubElement(pair, side)
                for j in sorted(group):
                    ET.SubElement(side_el, "transition", {"idref": f"t{j}"})
    return root


def to_pnml(net: PetriNet) -> str:
    """The PNML document of ``net``, pretty-printed, with an XML declaration.

    Args:
        net: the net to export.

    Returns:
        UTF-8-declared XML text ending with a newline.
    """
    root = to_pnml_tree(net)
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n"
