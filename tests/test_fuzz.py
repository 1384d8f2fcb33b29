"""Fuzzing, bounded: mutated real inputs and token soups never crash or hang a parser
or a command's core (see tests/fuzzing.py for the 10 000-input campaign)."""

from __future__ import annotations

import random
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.fuzzing import KINDS, TOKENS, generate, run_one

BOUNDED = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


@pytest.fixture(scope="module")
def workdir():  # type: ignore[no-untyped-def]
    with tempfile.TemporaryDirectory(prefix="skinet-fuzz-") as tmp:
        yield Path(tmp)


@pytest.mark.parametrize("kind", KINDS)
def test_mutated_real_inputs(kind: str, workdir: Path) -> None:
    @BOUNDED
    @given(st.integers(min_value=0, max_value=2**32))
    def one(seed: int) -> None:
        text = generate(kind, random.Random(seed))
        assert run_one(kind, text, workdir) is None, text

    one()


@pytest.mark.parametrize("kind", ["rl", "formula", "props"])
def test_token_soups(kind: str, workdir: Path) -> None:
    prefix = {"rl": "skillset s { ", "formula": "", "props": "p = "}[kind]

    @BOUNDED
    @given(st.lists(st.sampled_from(TOKENS), max_size=30))
    def one(tokens: list[str]) -> None:
        text = prefix + " ".join(tokens)
        assert run_one(kind, text, workdir) is None, text

    one()
