"""The examples in the docstrings of skinet/plan run as written (doctests)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import skinet.plan

MODULES = ["skinet.plan"] + [f"skinet.plan.{m.name}" for m in pkgutil.iter_modules(skinet.plan.__path__)]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.plan.systems import ROOT

    monkeypatch.chdir(ROOT)
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0
