"""Errors of the core library, each able to point at a source position."""

from __future__ import annotations

from dataclasses import dataclass


MAX_SHOWN = 200  # characters of a name (a path, an include) an error shows


def shown(text: str, limit: int = MAX_SHOWN) -> str:
    """``text``, or its first ``limit`` characters and its length when longer: an error
    echoing a name given as input stays short (a 5 000-character include name)."""
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} characters)"


@dataclass(frozen=True)
class Pos:
    """A position in a source text (1-based line and column)."""

    line: int
    column: int


class SkinetError(Exception):
    """Base class of every error the core raises on bad input."""


@dataclass
class Diagnostic:
    """One message about a source file, printed as ``FILE:LINE:COL: level: text``."""

    file: str
    pos: Pos | None
    level: str  # "error" or "warning"
    message: str

    def __str__(self) -> str:
        where = shown(self.file)
        if self.pos is not None:
            where = f"{where}:{self.pos.line}:{self.pos.column}"
        return f"{where}: {self.level}: {self.message}"


class SourceError(SkinetError):
    """Bad input text: carries one or more diagnostics (all of level ``error``)."""

    def __init__(self, diagnostics: list[Diagnostic]):
        self.diagnostics = diagnostics
        super().__init__("\n".join(str(d) for d in diagnostics))

    @classmethod
    def at(cls, file: str, pos: Pos | None, message: str) -> "SourceError":
        """One error at one position."""
        return cls([Diagnostic(file, pos, "error", message)])
