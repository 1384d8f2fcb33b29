"""Exports of a net: Tina, PNML, Graphviz, JSON (docs/semantics.md §3, *Interop*)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from skinet.lang.parser import parse_skillset
from skinet.net.build import build_net
from skinet.net.export import (
    FORMATS,
    JSON_FORMAT_VERSION,
    DuplicateNameError,
    NetFormatError,
    from_json,
    to_json,
)
from skinet.net.export.dot import to_dot
from skinet.net.export.pnml import PNML_NS, PTNET_TYPE, to_pnml
from skinet.net.export.tina import tina_name, to_tina
from skinet.net.petrinet import PetriNet, Transition
from tests.corpus import require_corpus

CORPUS = Path(__file__).resolve().parents[3] / "shared" / "corpus"
CORPUS_FILES = ["spot.rl", "manipulator.rl", "isae_robot/isae_robot.rl"]
NS = {"p": PNML_NS}
DOT = shutil.which("dot")
needs_dot = pytest.mark.skipif(DOT is None, reason="Graphviz 'dot' not installed (apt-get install graphviz)")

MINI = """
skillset mini {
    resource {
        power {
            state { Off On }
            initial Off
            transition all
        }
    }
    event {
        switch_on {
            guard power == Off
            effect power -> On
        }
    }
    skill move {
        precondition {
            powered: power == On
        }
        invariant {
            still_powered {
                guard power == On
            }
        }
        success arrived {}
        failure blocked {
            postcondition power == Off
        }
    }
}
"""

# Derived by hand from the docs/semantics.md §3 table: the failure's postcondition fixes
# `power`, so it has one variant per source state of `power`.
MINI_TINA = """\
net mini
pl {power.Off} (1)
pl {power.On}
pl e_move (1)
pl i_move
tr switch_on : switch_on {power.Off} -> {power.On}
tr {move.start} : {move.start} {power.On} e_move -> {power.On} i_move
tr {move.inv.still_powered} : {move.inv.still_powered} {power.Off} i_move -> {power.Off} e_move
tr {move.interrupt} : {move.interrupt} i_move -> e_move
tr {move.success.arrived} : {move.success.arrived} i_move -> e_move
tr {move.failure.blocked} : {move.failure.blocked} {power.Off} i_move -> {power.Off} e_move
tr {move.failure.blocked#2} : {move.failure.blocked} {power.On} i_move -> {power.Off} e_move
pr {move.inv.still_powered} > switch_on {move.start} {move.interrupt} \
{move.success.arrived} {move.failure.blocked} {move.failure.blocked#2}
"""

AWKWARD_PLACES = ("a}b", "c\\d", "{x}", 'q"uote', "sp ace", "<&>", "pl", "ok_name'", "n\nl", "tail\\")


@pytest.fixture(scope="module")
def mini() -> PetriNet:
    return build_net(parse_skillset(MINI, "mini.rl"))


@pytest.fixture(scope="module")
def awkward() -> PetriNet:
    """A hand-made net whose names need quoting in every format."""
    p = {name: i for i, name in enumerate(AWKWARD_PLACES)}
    ts = (
        Transition("t{1}", "t{1}", "event", frozenset({p["a}b"]}), frozenset({p["c\\d"]}), "s&s"),
        Transition("go:\\", "go", "start", frozenset({p["{x}"], p['q"uote']}),
                   frozenset({p["{x}"], p["sp ace"]}), "s&s", "k<1>"),
        Transition("tr", "tr", "invariant", frozenset({p["<&>"], p["pl"]}),
                   frozenset({p["ok_name'"]}), "s&s", "k<1>", "inv"),
        Transition('x"y#2', 'x"y', "success", frozenset({p["n\nl"]}), frozenset({p["tail\\"]}), "s&s", "k<1>"),
    )
    return PetriNet(
        "net {odd}", AWKWARD_PLACES, ts,
        (1 << p["a}b"]) | (1 << p["{x}"]) | (1 << p['q"uote']),
        ((frozenset({2}), frozenset({0, 1, 3})),),
    )


def _corpus_nets() -> list[PetriNet]:
    files = [CORPUS / f for f in CORPUS_FILES if (CORPUS / f).exists()]
    if not files:
        require_corpus()
    nets = []
    for f in files:
        skillset = parse_skillset(f.read_text(), str(f))
        nets += [build_net(skillset), build_net(skillset, eventless=True)]
    return nets


# --- a small reader of the Tina lines we write, to check quoting round trips ---

_TOKEN = re.compile(r"\{(?:\\.|[^\\{}])*\}|[^\s{}]+", re.S)


def _untina(token: str) -> str:
    if token.startswith("{"):
        return re.sub(r"\\(.)", r"\1", token[1:-1], flags=re.S)
    assert re.fullmatch(r"[A-Za-z0-9_']+", token), token
    return token


def _read_tina(text: str) -> dict[str, object]:
    """Net name, places with markings, transitions and priorities of a .net text.

    Keywords written bare start a declaration (our writer quotes names equal to
    a keyword), so the text is split at them rather than at newlines.
    """
    decls: list[list[str]] = []
    for token in _TOKEN.findall(text):
        if token in ("net", "pl", "tr", "pr"):
            decls.append([token])
        else:
            decls[-1].append(token)
    places: dict[str, bool] = {}
    transitions: dict[str, tuple[str, set[str], set[str]]] = {}
    priority: list[tuple[set[str], set[str]]] = []
    name = None
    for kind, *rest in decls:
        if kind == "net":
            name = _untina(rest[0])
        elif kind == "pl":
            places[_untina(rest[0])] = rest[1:] == ["(1)"]
        elif kind == "tr":
            assert rest[1] == ":"
            arrow = rest.index("->")
            transitions[_untina(rest[0])] = (
                _untina(rest[2]), {_untina(w) for w in rest[3:arrow]}, {_untina(w) for w in rest[arrow + 1:]}
            )
        else:
            gt = rest.index(">")
            priority.append(({_untina(w) for w in rest[:gt]}, {_untina(w) for w in rest[gt + 1:]}))
    return {"name": name, "places": places, "transitions": transitions, "priority": priority}


def _expected_tina(net: PetriNet) -> dict[str, object]:
    return {
        "name": net.name,
        "places": {p: bool(net.initial >> i & 1) for i, p in enumerate(net.places)},
        "transitions": {
            t.id: (t.name, {net.places[i] for i in t.pre}, {net.places[i] for i in t.post})
            for t in net.transitions
        },
        "priority": [
            ({net.transitions[j].id for j in h}, {net.transitions[j].id for j in lo}) for h, lo in net.priority
        ],
    }


# --- Tina ---


def test_tina_exact_text(mini: PetriNet) -> None:
    assert to_tina(mini) == MINI_TINA


def test_tina_names() -> None:
    assert tina_name("e_move") == "e_move"
    assert tina_name("x'") == "x'"
    assert tina_name("R.s") == "{R.s}"
    assert tina_name("k.start#2") == "{k.start#2}"
    assert tina_name("a:b") == "{a:b}"
    assert tina_name("a}b") == "{a\\}b}"
    assert tina_name("c\\d") == "{c\\\\d}"
    assert tina_name("{x}") == "{\\{x\\}}"
    assert tina_name("tr") == "{tr}"  # a keyword, quoted to be safe


def test_tina_awkward_round_trip(awkward: PetriNet) -> None:
    text = to_tina(awkward)
    assert text.startswith("net {net \\{odd\\}}\n")
    assert "pl {a\\}b} (1)\n" in text
    assert "tr {go:\\\\} : go {\\{x\\}} {q\"uote} -> {\\{x\\}} {sp ace}\n" in text
    assert _read_tina(text) == _expected_tina(awkward)


def test_tina_corpus_round_trip() -> None:
    for net in _corpus_nets():
        assert _read_tina(to_tina(net)) == _expected_tina(net), net.name


# --- PNML ---


def _pnml(net: PetriNet) -> ET.Element:
    root = ET.fromstring(to_pnml(net))
    assert root.tag == f"{{{PNML_NS}}}pnml"
    return root


def test_pnml_structure(mini: PetriNet) -> None:
    text = to_pnml(mini)
    assert text.startswith('<?xml version="1.0" encoding="UTF-8"?>\n')
    net_el = _pnml(mini).find("p:net", NS)
    assert net_el is not None and net_el.get("type") == PTNET_TYPE
    page = net_el.find("p:page", NS)
    assert page is not None
    places = page.findall("p:place", NS)
    transitions = page.findall("p:transition", NS)
    arcs = page.findall("p:arc", NS)
    assert [p.findtext("p:name/p:text", namespaces=NS) for p in places] == list(mini.places)
    assert [t.findtext("p:name/p:text", namespaces=NS) for t in transitions] == mini.transition_ids()
    assert len(arcs) == sum(len(t.pre) + len(t.post) for t in mini.transitions) == 22
    marked = {
        p.findtext("p:name/p:text", namespaces=NS): p.findtext("p:initialMarking/p:text", namespaces=NS)
        for p in places
        if p.find("p:initialMarking", NS) is not None
    }
    assert marked == {"power.Off": "1", "e_move": "1"}
    ids = [e.get("id") for e in net_el.iter() if e.get("id") is not None]
    assert len(ids) == len(set(ids))
    # Every arc joins a place and a transition.
    kinds = {p.get("id"): "p" for p in places} | {t.get("id"): "t" for t in transitions}
    assert all({kinds[a.get("source")], kinds[a.get("target")]} == {"p", "t"} for a in arcs)


def test_pnml_arcs_and_priority_match_net(mini: PetriNet) -> None:
    net_el = _pnml(mini).find("p:net", NS)
    assert net_el is not None
    names = {
        e.get("id"): e.findtext("p:name/p:text", namespaces=NS)
        for e in net_el.iter()
        if e.tag in (f"{{{PNML_NS}}}place", f"{{{PNML_NS}}}transition")
    }
    arcs = {(names[a.get("source")], names[a.get("target")]) for a in net_el.iter(f"{{{PNML_NS}}}arc")}
    expected = set()
    for t in mini.transitions:
        expected |= {(mini.places[i], t.id) for i in t.pre} | {(t.id, mini.places[i]) for i in t.post}
    assert arcs == expected
    tool = net_el.find("p:toolspecific", NS)
    assert tool is not None and tool.get("tool") == "skinet" and tool.get("version") == "1"
    pairs = [
        (
            {names[t.get("idref")] for t in pr.findall("p:high/p:transition", NS)},
            {names[t.get("idref")] for t in pr.findall("p:low/p:transition", NS)},
        )
        for pr in tool.findall("p:priority", NS)
    ]
    assert pairs == [({"move.inv.still_powered"}, set(mini.transition_ids()) - {"move.inv.still_powered"})]


def test_pnml_awkward_names(awkward: PetriNet) -> None:
    root = _pnml(awkward)
    page = root.find("p:net/p:page", NS)
    assert page is not None
    assert [p.findtext("p:name/p:text", namespaces=NS) for p in page.findall("p:place", NS)] == list(
        AWKWARD_PLACES
    )
    assert [t.findtext("p:name/p:text", namespaces=NS) for t in page.findall("p:transition", NS)] == (
        awkward.transition_ids()
    )
    assert root.findtext("p:net/p:name/p:text", namespaces=NS) == "net {odd}"


# --- JSON ---


def test_json_round_trip(mini: PetriNet, awkward: PetriNet) -> None:
    for net in (mini, awkward, *_corpus_nets()):
        data = to_json(net)
        assert data["format_version"] == JSON_FORMAT_VERSION
        back = from_json(json.loads(json.dumps(data)))
        assert back.name == net.name
        assert back.places == net.places
        assert back.initial == net.initial
        assert back.priority == net.priority
        assert [(t.id, t.pre, t.post) for t in back.transitions] == [(t.id, t.pre, t.post) for t in net.transitions]
        assert [(t.pre_mask, t.post_mask) for t in back.transitions] == [
            (t.pre_mask, t.post_mask) for t in net.transitions
        ]
        assert back == net


def test_json_content(mini: PetriNet) -> None:
    data = to_json(mini)
    assert data["initial"] == ["power.Off", "e_move"]
    start = data["transitions"][1]
    assert start == {
        "id": "move.start", "name": "move.start", "kind": "start", "skillset": "mini",
        "skill": "move", "element": None, "controllable": True,
        "pre": ["power.On", "e_move"], "post": ["power.On", "i_move"],
    }
    assert data["priority"][0]["high"] == ["move.inv.still_powered"]


def test_json_rejects_bad_input(mini: PetriNet) -> None:
    data = to_json(mini)
    with pytest.raises(NetFormatError, match="format_version"):
        from_json({**data, "format_version": 2})
    bad = json.loads(json.dumps(data))
    bad["transitions"][0]["pre"] = ["nowhere"]
    with pytest.raises(NetFormatError, match="nowhere"):
        from_json(bad)
    bad = json.loads(json.dumps(data))
    bad["priority"][0]["low"].append("ghost")
    with pytest.raises(NetFormatError, match="ghost"):
        from_json(bad)
    with pytest.raises(NetFormatError, match="malformed"):
        from_json({"format_version": 1, "places": []})


# --- Graphviz ---


def test_dot_mentions_everything(mini: PetriNet) -> None:
    text = to_dot(mini)
    assert text.startswith('digraph "mini" {')
    for p in mini.places:
        assert f'"p:{p}"' in text
    for t in mini.transitions:
        assert f'"t:{t.id}"' in text
    assert '"p:power.Off" [shape="circle", label="power.Off\\n\u25cf"];' in text
    assert '"p:power.On" [shape="circle", label="power.On"];' in text
    assert '"p:power.On" -> "t:move.start" [dir="both"];' in text
    assert '"p:e_move" -> "t:move.start";' in text
    assert text.count("fillcolor=") == 3  # one invariant, start and interrupt


def test_dot_quoting(awkward: PetriNet) -> None:
    text = to_dot(awkward)
    assert '"p:a}b"' in text
    assert '"p:c\\\\d"' in text
    assert '"p:q\\"uote"' in text
    assert '"p:n\\nl"' in text
    assert '"p:tail\\\\"' in text
    # No raw newline inside a quoted string: every line is a whole statement.
    assert all(line.rstrip().endswith((";", "{", "}")) for line in text.splitlines())


def test_dot_clusters(mini: PetriNet) -> None:
    text = to_dot(mini, clusters=True)
    cluster = text[text.index('subgraph "cluster_0"'):text.index("  }\n")]
    assert 'label="move";' in cluster
    assert '"p:e_move"' in cluster and '"p:i_move"' in cluster
    assert '"p:power.On"' not in cluster and '"t:switch_on"' not in cluster


def _dot_json(text: str) -> dict[str, object]:
    assert DOT is not None
    done = subprocess.run([DOT, "-Tjson"], input=text.encode(), capture_output=True, timeout=60)
    assert done.returncode == 0, done.stderr.decode()
    return json.loads(done.stdout)


@needs_dot
def test_dot_accepted_by_graphviz(mini: PetriNet, awkward: PetriNet) -> None:
    assert DOT is not None
    nets = [mini, awkward, *_corpus_nets()]
    for net in nets:
        for clusters in (False, True):
            text = to_dot(net, clusters=clusters)
            done = subprocess.run([DOT, "-Tsvg"], input=text.encode(), capture_output=True, timeout=60)
            assert done.returncode == 0, (net.name, done.stderr.decode())
            assert b"<svg" in done.stdout
            graph = _dot_json(text)
            nodes = [o for o in graph["objects"] if "nodes" not in o]  # type: ignore[attr-defined]
            assert len(nodes) == len(net.places) + len(net.transitions), net.name
            edges = sum(len(t.pre | t.post) for t in net.transitions)
            assert len(graph.get("edges", [])) == edges, net.name  # type: ignore[arg-type]


# --- registry ---


def test_formats(mini: PetriNet) -> None:
    assert set(FORMATS) == {"json", "tina", "pnml", "dot", "promela"}
    for name, export in FORMATS.items():
        text = export(mini)
        assert isinstance(text, str) and text.endswith("\n"), name
    assert FORMATS["tina"](mini) == MINI_TINA
    assert from_json(json.loads(FORMATS["json"](mini))) == mini


def test_duplicate_names_rejected(mini: PetriNet) -> None:
    twice = PetriNet(mini.name, mini.places, mini.transitions + mini.transitions[:1], mini.initial)
    for name, export in FORMATS.items():
        with pytest.raises(DuplicateNameError, match="switch_on"):
            export(twice)
    same_place = PetriNet("p", ("x", "x"), (), 0)
    with pytest.raises(DuplicateNameError, match="place"):
        to_tina(same_place)
