"""The predictor service: state-space exploration and mu1 over Zenoh (docs/semantics.md §1, §6).

Its names are loaded on first use, so that ``python -m services.predictor.sandbox`` (a worker
process) does not import the service first."""

from __future__ import annotations

from typing import Any

__all__ = ["Predictor", "start_predictor"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from services.predictor import service

        return getattr(service, name)
    raise AttributeError(f"module 'services.predictor' has no attribute '{name}'")
