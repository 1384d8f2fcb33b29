"""Where the third-party test corpus is, and how a test that needs it says so where it is absent.

The corpus (real skillset files and ROS 2 message definitions written by others) is
read in place from ``shared/corpus`` beside the repository root and never copied into
the project.  Tests that read it are marked ``corpus``; ``tests/conftest.py`` skips
them where it is absent and sums them up in one line of the summary.
"""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CORPUS = REPO.parent / "shared" / "corpus"
CORPUS_ABSENT = (f"needs the third-party test corpus ../shared/corpus ({CORPUS}), absent here: put the project's "
                 "shared/ folder beside the repository to run these (CI has it)")


def require_corpus() -> Path:
    """The corpus folder; skips the calling test (with the one reason the summary folds) where it is absent."""
    if not CORPUS.is_dir():
        pytest.skip(CORPUS_ABSENT)
    return CORPUS
