"""DDS tests: the real zenoh-plugin-ros2dds (built from the cargo workspace) and CycloneDDS participants."""

from __future__ import annotations


def pytest_configure(config) -> None:
    config.addinivalue_line("markers", "slow: builds the cargo workspace on first use (minutes; part of `make test`)")
