"""The README's and docs/'s examples reproduce as written, and their links resolve.

Every ``$ skinet ...`` line of a code block of README.md or of a page of docs/ is
run from the repository root and its output compared with the lines that follow it
(up to the next ``$`` line or the end of the block).  ``...`` on a line of its own stands for
any number of lines, inside a line for any text; otherwise lines must match
exactly and in order, the first at the start and the last at the end of the
output.  The expectations are read from the README itself, so a changed output
format fails here until the README shows it.  The command tables are checked
too: every option they name exists in the command's ``--help``.
"""

from __future__ import annotations

import argparse
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest

import services.bridge_ros2.__main__ as bridge_main
import services.dashboard.__main__ as dashboard_main
import services.monitor.__main__ as monitor_main
import services.pilot.__main__ as pilot_main
import services.predictor.__main__ as predictor_main
import services.simulator.__main__ as simulator_main
from skinet_cli.main import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
PAGES = {p.relative_to(ROOT).as_posix(): p.read_text(encoding="utf-8")
         for p in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]}
ELLIPSIS = "..."


@dataclass(frozen=True)
class Example:
    line: int  # of the ``$`` line in its page
    command: str
    expected: tuple[str, ...]
    page: str = "README.md"


def examples(text: str, page: str = "README.md") -> list[Example]:
    """The ``$ skinet`` commands of a page's code blocks with their expected output."""
    found: list[Example] = []
    in_block = False
    current: tuple[int, str, list[str]] | None = None
    for n, line in enumerate(text.splitlines(), 1):
        if line.startswith("```"):
            if current is not None:
                found.append(Example(current[0], current[1], tuple(current[2]), page))
                current = None
            in_block = not in_block
        elif in_block and line.startswith("$ "):
            if current is not None:
                found.append(Example(current[0], current[1], tuple(current[2]), page))
            current = (n, line[2:], [])
        elif current is not None:
            current[2].append(line)
    return found


def _line_matches(pattern: str, line: str) -> bool:
    if ELLIPSIS not in pattern or pattern == ELLIPSIS:
        return pattern == line
    return re.fullmatch(".*".join(map(re.escape, pattern.split(ELLIPSIS))), line) is not None


def matches(expected: tuple[str, ...], actual: list[str]) -> bool:
    """Whether ``actual`` is ``expected`` with each ``...`` line standing for any lines."""
    def at(i: int, j: int) -> bool:
        if i == len(expected):
            return j == len(actual)
        if expected[i] == ELLIPSIS:
            return any(at(i + 1, k) for k in range(j, len(actual) + 1))
        return j < len(actual) and _line_matches(expected[i], actual[j]) and at(i + 1, j + 1)

    return at(0, 0)


EXAMPLES = [e for page, text in PAGES.items() for e in examples(text, page)]


def test_the_docs_have_examples() -> None:
    assert len(EXAMPLES) >= 5
    assert all(e.command.startswith("skinet ") for e in EXAMPLES)
    assert {e.page for e in EXAMPLES} >= {"docs/commands.md", "docs/how-it-works.md", "docs/planning.md"}


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda e: f"{e.page}:{e.line}")
def test_readme_example(example: Example, capsys: pytest.CaptureFixture[str],
                        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    code = main(shlex.split(example.command)[1:])
    out, err = capsys.readouterr()
    where = f"{example.page}:{example.line}"
    assert code == 0, f"{where}: {example.command}\n{err}"
    assert matches(example.expected, out.splitlines()), (
        f"{where}: {example.command}\n--- the page shows:\n" + "\n".join(example.expected)
        + "\n--- the command prints:\n" + out)


def test_matcher() -> None:
    assert matches(("a", ELLIPSIS, "c"), ["a", "b", "b", "c"])
    assert matches(("a", ELLIPSIS), ["a"])
    assert not matches(("a", "c"), ["a", "b", "c"])
    assert not matches(("a",), ["a", "b"])
    assert matches(("took ... ms",), ["took 3.5 ms"])
    assert not matches(("took ... ms",), ["took 3.5 s"])


# -- the command tables -------------------------------------------------------------------------

SERVICES = {"services.monitor": monitor_main, "services.predictor": predictor_main,
            "services.bridge_ros2": bridge_main, "services.simulator": simulator_main,
            "services.dashboard": dashboard_main, "services.pilot": pilot_main}


def _help(usage: str) -> str:
    """The ``--help`` text of the command a table row shows."""
    words = usage.split()
    if words[0] == "skinet":
        (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
        return sub.choices[words[1]].format_help()
    return SERVICES[words[2]].build_parser().format_help()


def _table_commands(text: str) -> list[str]:
    """The usage text of each ``skinet`` and ``python -m services.*`` row of the README's tables."""
    return re.findall(r"^\| (?:[a-z_0-9]+ \| )?`((?:skinet|python -m services\.[a-z_0-9]+) [^`]*)`", text, re.M)


TABLE = [u for text in PAGES.values() for u in _table_commands(text)]


def test_the_tables_name_every_command() -> None:
    named = {u.split()[1] if u.startswith("skinet") else u.split()[2] for u in TABLE}
    assert named == {"demo", "conform", "run", "router", "record", "rosbag", "timeline", "replay", "parse", "net", "unsafe",
                     "explore", "ctl", "plan", "goal", "dashboard", "watch", "check", "foxglove", "client-config", *SERVICES}


@pytest.mark.parametrize("usage", TABLE, ids=[u.split(" [")[0] for u in TABLE])
def test_table_options_exist(usage: str) -> None:
    text = _help(usage)
    options = re.findall(r"(?<![\w-])(--?[a-z][a-z0-9-]*)", usage)
    missing = [o for o in options if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", text)]
    assert missing == [], f"README names {missing} for `{usage}`, which its --help does not list"


# -- links --------------------------------------------------------------------------------------

def _slug(heading: str) -> str:
    """The anchor GitHub gives a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(text: str) -> set[str]:
    found, fence = set(), False
    for line in text.splitlines():
        if line.startswith("```"):
            fence = not fence
        elif not fence and line.startswith("#"):
            found.add(_slug(line.lstrip("#")))
    return found


def broken_links(pages: dict[str, str], root: Path) -> list[str]:
    """``page: target`` for every relative link of ``pages`` whose file or heading does not exist."""
    broken = []
    for page, text in pages.items():
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if target.startswith(("http://", "https://")):
                continue
            path, _, anchor = target.partition("#")
            if not path:
                if anchor not in _anchors(text):
                    broken.append(f"{page}: {target} (no such heading)")
                continue
            file = (root / page).parent / path
            if not file.exists():
                broken.append(f"{page}: {target} (no such file)")
            elif anchor and file.suffix == ".md" and anchor not in _anchors(file.read_text(encoding="utf-8")):
                broken.append(f"{page}: {target} (no such heading)")
    return broken


def test_every_link_of_the_docs_resolves() -> None:
    assert broken_links(PAGES, ROOT) == []


def test_a_broken_link_is_found(tmp_path: Path) -> None:
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# A page\n\n## Its part\n", encoding="utf-8")
    pages = {"README.md": "[ok](docs/a.md#its-part) [gone](docs/b.md) [typo](docs/a.md#its-prat) [here](#a-page)"}
    assert broken_links(pages, tmp_path) == ["README.md: docs/b.md (no such file)",
                                             "README.md: docs/a.md#its-prat (no such heading)",
                                             "README.md: #a-page (no such heading)"]
