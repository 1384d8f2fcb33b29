"""Deployment tests: ACL router (no containers) and the compose stack (``slow``)."""

from __future__ import annotations


def pytest_configure(config) -> None:
    config.addinivalue_line("markers", "slow: builds images and runs containers (minutes; part of `make test`)")
