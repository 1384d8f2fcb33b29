"""Export to Tina's textual ``.net`` format (docs/semantics.md §3, *Interop*).

Format reference: the ``.net`` grammar shipped with Tina (``doc/formats/net.txt``,
mirrored in lip6/ITSTools ``coloane/extensions/importExportTINA/doc/formats/net.txt``)::

    netdesc ::= 'net' <net>
    trdesc  ::= 'tr' <transition> {":" <label>} {<interval>} {<tinput> -> <toutput>}
    pldesc  ::= 'pl' <place> {":" <label>} {(<marking>)} {<pinput> -> <poutput>}
    prdesc  ::= 'pr' (<transition>)+ ("<"|">") (<transition>)+
    net, place, transition, label ::= ANAME | '{'QNAME'}'

where ANAME is a non-empty string of letters, digits, primes ``'`` and
underscores, and QNAME is any string between braces in which ``{``, ``}`` and
``\\`` are prefixed by ``\\``.  Lines starting with ``#`` are comments.

Choices made here:

* every place is declared by a ``pl`` line, in place order (so Tina numbers
  places as we do, and places no transition touches are kept); a marked place
  carries ``(1)``;
* a test (a place in both ``pre`` and ``post``) is written as the place on both
  sides of ``->``, i.e. a self-loop, not as Tina's ``?1`` test arc;
* each transition is labelled with its logical name (docs/semantics.md §3: variants such as
  ``k.start#2`` are shown with their logical name ``k.start``);
* each priority pair ``(high, low)`` becomes one line ``pr H1 H2 ... > L1 L2 ...``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from skinet.net.export._common import check_unique_names
from skinet.net.petrinet import PetriNet

_ANAME = re.compile(r"[A-Za-z0-9_']+")
# Declaration keywords of the format: quoted to keep a line unambiguous.
_KEYWORDS = frozenset({"net", "pl", "tr", "lb", "pr"})


def tina_name(name: str) -> str:
    """``name`` as a Tina identifier: bare if it is an ANAME, else ``{...}``-quoted."""
    if _ANAME.fullmatch(name) and name not in _KEYWORDS:
        return name
    escaped = name.replace("\\", "\\\\").replace("{", "\\{").replace("}", "\\}")
    return "{" + escaped + "}"


def _names(names: Iterable[str]) -> str:
    return " ".join(tina_name(n) for n in names)


def to_tina(net: PetriNet) -> str:
    """The ``.net`` text of ``net``, with ``pr`` lines for its priority relation.

    Args:
        net: the net to export.

    Returns:
        The text, one declaration per line, ending with a newline.

    Raises:
        DuplicateNameError: two places or two transitions share a name (Tina
            would merge them).
    """
    check_unique_names(net)
    lines = [f"net {tina_name(net.name)}"]
    for i, place in enumerate(net.places):
        mark = " (1)" if net.initial >> i & 1 else ""
        lines.append(f"pl {tina_name(place)}{mark}")
    for t in net.transitions:
        words = ["tr", tina_name(t.id), ":", tina_name(t.name)]
        words += [tina_name(net.places[i]) for i in sorted(t.pre)]
        words.append("->")
        words += [tina_name(net.places[i]) for i in sorted(t.post)]
        lines.append(" ".join(words))
    for high, low in net.priority:
        if high and low:  # the grammar wants at least one transition per side
            hi = _names(net.transitions[i].id for i in sorted(high))
            lo = _names(net.transitions[i].id for i in sorted(low))
            lines.append(f"pr {hi} > {lo}")
    return "\n".join(lines) + "\n"
