"""LALR tables cached across processes (skinet/lang/larkcache.py): same diagnostics, never stale."""

from __future__ import annotations

from pathlib import Path

import pytest
from lark import Lark, UnexpectedInput

from skinet.lang import parser as skillset_parser
from skinet.lang.larkcache import cache_dir, cached_lark
from skinet.lang.larkerrors import syntax_diagnostic
from skinet.props import parser as props_parser

SKILLSET = Path(skillset_parser.__file__).with_name("skillset.lark")
FORMULA = Path(props_parser.__file__).with_name("formula.lark")
SKILLSET_OPTIONS = dict(start="start", parser="lalr", lexer="contextual", propagate_positions=True,
                        maybe_placeholders=False)

# Every kind of syntax error of the two grammars: unexpected token, unexpected end of input,
# unexpected character, unterminated comment, an error after LALR reductions.
BAD_SKILLSETS = [
    "skillset s { skill k { foo } }",
    "skillset s { skill k { precondition p: r == } }",
    "skillset s {\n  skill k { precondition p: (r == A }\n}",
    "skillset s { event e { guard r == A and } }",
    "skillset s { data { x: y: T } }",
    "type { A }\ntype B C\nskillset s {}",
    "skillset s { skill k { progress { period fast } } }",
    "skillset s<T,> {}",
    "skillset s { event e { guard r = A } }",
    "skillset s # {}",
    "skillset s { resource r { state { A } initial A transition { A - B } } }",
    "skillset s { /* never closed",
    "skillset s {",
    "skillset s { resource r { state { A B }",
    "",
]
BAD_FORMULAS = ["AG (", "spot:Busy and", "AG not (spot:Busy and manipulator:Busy", "E [ a U", "EF ! x", "A [ a W b ]"]


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return tmp_path / "xdg" / "skinet-live"


def _diagnostics(parser: Lark, texts: list[str]) -> list[str]:
    out = []
    for text in texts:
        with pytest.raises(UnexpectedInput) as info:
            parser.parse(text)
        out.append(str(syntax_diagnostic(parser, info.value, text, "f.rl")))
    return out


def test_cache_dir_follows_xdg(cache: Path) -> None:
    assert cache_dir() == cache


def test_second_process_loads_the_tables(cache: Path) -> None:
    built = cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    assert built.source_path != "<deserialized>"
    (written,) = cache.iterdir()
    assert written.name.startswith("skillset-start-") and written.name.endswith(".lark.pickle")
    assert oct(cache.stat().st_mode & 0o777) == "0o700"
    loaded = cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    assert loaded.source_path == "<deserialized>"  # lark's Lark.load, not a rebuild
    assert [t.name for t in loaded.terminals] == [t.name for t in built.terminals]
    assert loaded.lexer_conf.ignore == built.lexer_conf.ignore == ["LINE_COMMENT", "BLOCK_COMMENT", "__IGNORE_2"]


def test_loaded_tables_give_the_same_syntax_errors(cache: Path) -> None:
    built = cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    loaded = cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    assert loaded.source_path == "<deserialized>"
    expected = _diagnostics(built, BAD_SKILLSETS)
    assert _diagnostics(loaded, BAD_SKILLSETS) == expected
    assert expected[0] == ("f.rl:1:24: error: unexpected 'foo', expected one of: 'failure', 'input', 'interrupt', "
                           "'invariant', 'output', 'precondition', 'progress', 'start', 'success', '}'")
    assert expected[11] == "f.rl:1:14: error: unterminated comment '/*'"
    for start in ("expr", "properties"):
        options = dict(start=start, parser="lalr", propagate_positions=True, maybe_placeholders=False)
        built, loaded = cached_lark(FORMULA, **options), cached_lark(FORMULA, **options)
        assert loaded.source_path == "<deserialized>"
        assert _diagnostics(loaded, BAD_FORMULAS) == _diagnostics(built, BAD_FORMULAS)


def test_loaded_tables_give_the_same_trees(cache: Path) -> None:
    text = (Path(__file__).parents[2] / "skillsets" / "spot.rl").read_text()
    built = cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    loaded = cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    a, b = built.parse(text), loaded.parse(text)
    assert a == b
    assert [(n.meta.line, n.meta.column) for n in a.iter_subtrees()] == [
        (n.meta.line, n.meta.column) for n in b.iter_subtrees()]


def test_a_changed_grammar_is_never_served_stale(cache: Path, tmp_path: Path) -> None:
    grammar = tmp_path / "g.lark"
    grammar.write_text('start: "a"\n')
    assert cached_lark(grammar, parser="lalr").parse("a")
    grammar.write_text('start: "b"\n')
    changed = cached_lark(grammar, parser="lalr")
    assert changed.source_path != "<deserialized>"  # a new hash: built, not loaded
    assert changed.parse("b")
    with pytest.raises(UnexpectedInput):
        changed.parse("a")
    assert len(list(cache.iterdir())) == 2
    assert cached_lark(grammar, parser="lalr").source_path == "<deserialized>"


def test_options_are_part_of_the_key(cache: Path, tmp_path: Path) -> None:
    grammar = tmp_path / "g.lark"
    grammar.write_text("start: a | b\na: \"a\"\nb: \"b\"\n")
    cached_lark(grammar, parser="lalr", start="start")
    assert cached_lark(grammar, parser="lalr", start="a").source_path != "<deserialized>"
    assert cached_lark(grammar, parser="lalr", start="a").parse("a").data == "a"


def test_a_damaged_cache_file_is_rebuilt(cache: Path) -> None:
    cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    (written,) = cache.iterdir()
    written.write_bytes(written.read_bytes()[:1000])  # as if a writer had died half-way
    rebuilt = cached_lark(SKILLSET, **SKILLSET_OPTIONS)
    assert rebuilt.source_path != "<deserialized>"
    assert _diagnostics(rebuilt, BAD_SKILLSETS[:1]) == _diagnostics(cached_lark(SKILLSET, **SKILLSET_OPTIONS),
                                                                    BAD_SKILLSETS[:1])
    assert cached_lark(SKILLSET, **SKILLSET_OPTIONS).source_path == "<deserialized>"


def test_an_unwritable_cache_only_costs_time(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")  # mkdir under a file fails, for root too
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    assert cached_lark(SKILLSET, **SKILLSET_OPTIONS).parse("skillset s {}")
    assert cached_lark(SKILLSET, **SKILLSET_OPTIONS).source_path != "<deserialized>"
    assert list(tmp_path.iterdir()) == [blocked]
