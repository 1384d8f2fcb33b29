"""Export to Graphviz DOT, for pictures of a net (docs/semantics.md §3, *Interop*).

Places are circles labelled with their name and, when initially marked, a
``●``; transitions are boxes labelled with their logical name (docs/semantics.md §3 shows
variants such as ``k.start#2`` as ``k.start``; the unique id is the tooltip).
Invariant transitions, which have priority over the rest, are filled in
:data:`INVARIANT_COLOR`; controllable ones (skill start and interrupt, the
operator's commands) in :data:`CONTROLLABLE_COLOR`.  A test (a place in both
``pre`` and ``post``) is one double-headed arc (``dir=both``).  Node ids are
``"p:<place>"`` and ``"t:<transition id>"`` so a place and a transition may
share a name; every id and label is a quoted DOT string.
"""

from __future__ import annotations

from collections import defaultdict

from skinet.net.export._common import check_unique_names
from skinet.net.petrinet import PetriNet, Transition

INVARIANT_COLOR = "#f4b6b6"
CONTROLLABLE_COLOR = "#b6d4f4"
MARK = "\u25cf"  # ●


def dot_quote(text: str) -> str:
    """``text`` as a double-quoted DOT string (``\\``, ``"`` and newlines escaped)."""
    escaped = text.replace("\\", "\\\\").replace('"', '\\"')
    escaped = escaped.replace("\r\n", "\\n").replace("\n", "\\n").replace("\r", "\\n")
    return f'"{escaped}"'


def _attrs(**attrs: str) -> str:
    return "[" + ", ".join(f"{k}={dot_quote(v)}" for k, v in attrs.items()) + "]"


def _place_id(net: PetriNet, i: int) -> str:
    return dot_quote(f"p:{net.places[i]}")


def _transition_id(t: Transition) -> str:
    return dot_quote(f"t:{t.id}")


def _place_node(net: PetriNet, i: int) -> str:
    label = net.places[i] + (f"\n{MARK}" if net.initial >> i & 1 else "")
    return f"{_place_id(net, i)} {_attrs(shape='circle', label=label)};"


def _transition_node(t: Transition) -> str:
    attrs = {"shape": "box", "label": t.name, "tooltip": t.id}
    if t.is_invariant:
        attrs.update(style="filled", fillcolor=INVARIANT_COLOR)
    elif t.controllable:
        attrs.update(style="filled", fillcolor=CONTROLLABLE_COLOR)
    return f"{_transition_id(t)} {_attrs(**attrs)};"


def _skill_places(net: PetriNet, members: list[int]) -> set[int]:
    """The idle and running places of one skill, found from the net's structure.

    The idle place is consumed (not tested) by every start variant and produced
    by every other transition of the skill; the running place the other way
    round (docs/semantics.md §3 table).
    """
    starts = [net.transitions[j] for j in members if net.transitions[j].kind == "start"]
    stops = [net.transitions[j] for j in members if net.transitions[j].kind != "start"]
    if not starts or not stops:
        return set()
    idle = set.intersection(*(set(t.pre - t.post) for t in starts), *(set(t.post - t.pre) for t in stops))
    running = set.intersection(*(set(t.post - t.pre) for t in starts), *(set(t.pre - t.post) for t in stops))
    return idle | running


def to_dot(net: PetriNet, clusters: bool = False) -> str:
    """A Graphviz ``digraph`` of ``net``.

    Args:
        net: the net to draw.
        clusters: group each skill's transitions, idle and running places in
            a ``cluster`` subgraph.

    Returns:
        DOT text ending with a newline; render with e.g. ``dot -Tsvg``.

    Raises:
        DuplicateNameError: two places or two transitions share a name (their
            nodes would merge).
    """
    check_unique_names(net)
    lines = [f"digraph {dot_quote(net.name)} {{", '  rankdir="LR";']
    placed: set[int] = set()
    drawn: set[int] = set()
    if clusters:
        skills: dict[tuple[str, str], list[int]] = defaultdict(list)
        for j, t in enumerate(net.transitions):
            if t.skill is not None:
                skills[(t.skillset, t.skill)].append(j)
        several = len({skillset for skillset, _ in skills}) > 1
        for n, ((skillset, skill), members) in enumerate(skills.items()):
            label = f"{skillset}.{skill}" if several else skill
            lines.append(f"  subgraph {dot_quote(f'cluster_{n}')} {{")
            lines.append(f"    label={dot_quote(label)};")
            for i in sorted(_skill_places(net, members) - placed):
                lines.append("    " + _place_node(net, i))
                placed.add(i)
            for j in members:
                lines.append("    " + _transition_node(net.transitions[j]))
                drawn.add(j)
            lines.append("  }")
    for i in range(len(net.places)):
        if i not in placed:
            lines.append("  " + _place_node(net, i))
    for j, t in enumerate(net.transitions):
        if j not in drawn:
            lines.append("  " + _transition_node(t))
    for t in net.transitions:
        tid = _transition_id(t)
        for i in sorted(t.pre | t.post):
            pid = _place_id(net, i)
            if i in t.pre and i in t.post:
                lines.append(f'  {pid} -> {tid} [dir="both"];')
            elif i in t.pre:
                lines.append(f"  {pid} -> {tid};")
            else:
                lines.append(f"  {tid} -> {pid};")
    lines.append("}")
    return "\n".join(lines) + "\n"
