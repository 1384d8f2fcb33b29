"""LALR parsers built once per grammar, not once per process.

Building the LALR tables of ``skillset.lark`` takes about 0.1 s, a third of
the start-up of a one-shot command such as ``skinet unsafe``; loading them
back takes about 0.01 s.  The tables are kept in
``$XDG_CACHE_HOME/skinet-live`` (default ``~/.cache/skinet-live``), in a file
named by a hash of the grammar text, the options, lark's version and
Python's: a changed grammar (or lark, or Python) is a different file, so a
stale table is never loaded.  The grammars stay in their ``.lark`` files.

A loaded parser is lark's own deserialised :class:`~lark.Lark` (``Lark.load``):
same terminals, same tables, so syntax errors carry the same positions and
expected-token lists (``tests/lang/test_larkcache.py`` compares both paths on
every error case).  Anything wrong with the cache (missing, unreadable,
truncated by a concurrent writer, read-only home) only means the tables are
built as before.
"""

from __future__ import annotations

import hashlib
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import lark
from lark import Lark


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/skinet-live``, by default ``~/.cache/skinet-live``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "skinet-live"


def cache_path(grammar_path: Path, grammar: str, options: dict[str, Any]) -> Path:
    """The file holding the tables of ``grammar`` built with ``options``."""
    key = "\0".join([grammar, repr(sorted(options.items())), lark.__version__, "%d.%d" % sys.version_info[:2]])
    digest = hashlib.sha256(key.encode("utf-8")).hexdigest()[:24]
    start = options.get("start", "start")
    return cache_dir() / f"{grammar_path.stem}-{start}-{digest}.lark.pickle"


def cached_lark(grammar_path: Path, **options: Any) -> Lark:
    """``Lark(grammar_path.read_text(), **options)``, its LALR tables read from the cache when there.

    ``options`` must be plain values (no transformer, no callbacks): they are
    part of the cache key and restored by ``Lark.load``.
    """
    grammar = grammar_path.read_text(encoding="utf-8")
    path = cache_path(grammar_path, grammar, options)
    try:
        with open(path, "rb") as f:
            return Lark.load(f)
    except Exception:  # noqa: BLE001 - missing or unusable cache file: build the tables instead
        pass
    parser = Lark(grammar, **options)
    _save(parser, path)
    return parser


def _save(parser: Lark, path: Path) -> None:
    """Write the tables atomically (a concurrent reader sees the old file or the whole new one)."""
    try:
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                parser.save(f)
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise
    except OSError:  # read-only or full file system: the next process builds the tables again
        pass
