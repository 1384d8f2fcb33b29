"""DDS tests: the real zenoh-plugin-ros2dds (built from the cargo workspace) and CycloneDDS participants."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from gateway import Gateway
from native_build import native_binary


def pytest_configure(config) -> None:
    config.addinivalue_line("markers", "slow: builds the cargo workspace on first use (minutes; part of `make test`)")


@pytest.fixture(scope="module")
def plugin() -> Path:
    return native_binary("skinet-ros2dds-bridge")


@pytest.fixture
def gateway_factory(plugin: Path, tmp_path: Path) -> Iterator:
    gateways: list[Gateway] = []

    def start(**options) -> Gateway:
        gateways.append(Gateway(plugin, tmp_path, **options))
        return gateways[-1]

    yield start
    for g in gateways:
        g.close()
        print(f"--- zenoh-plugin-ros2dds (exit {g.proc.returncode}) ---\n{g.output()}")
