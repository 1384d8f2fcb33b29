"""The project's cargo workspace, built once per machine for the tests that run its binaries.

``native_binary(name)`` runs ``scripts/build-native.sh`` (a debug build of the whole
workspace into ``~/.cache/skinet-live/cargo-target``, shared by every clone) and
returns the binary's path, or skips the test with the reason when cargo or cmake
is missing.  cargo rebuilds only what changed: after the first build (about 12
minutes on 2 idle cores, see docs/development.md) a call costs about a second.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "skinet-live"
TARGET = Path(os.environ.get("CARGO_TARGET_DIR", CACHE / "cargo-target"))
BUILD_TIMEOUT = 45 * 60  # a clean build on 2 busy cores, with margin


def missing_tools() -> list[str]:
    """What a clean build of the workspace needs and this machine lacks."""
    missing = [tool for tool in ("cargo", "cmake") if shutil.which(tool) is None]
    return missing


@functools.cache
def _build() -> str:
    """'' once the workspace is built, else why not (cached: one build per test session)."""
    missing = missing_tools()
    if missing:
        return (f"{' and '.join(missing)} not installed: the cargo workspace (zenoh-plugin-ros2dds, "
                f"examples/rust_client) cannot be built; scripts/install-test-deps.sh installs cmake")
    r = subprocess.run([str(REPO / "scripts" / "build-native.sh")], capture_output=True, text=True,
                       env={**os.environ, "CARGO_TARGET_DIR": str(TARGET)}, timeout=BUILD_TIMEOUT)
    if r.returncode != 0:
        pytest.fail(f"scripts/build-native.sh failed:\n{r.stderr[-4000:]}")
    return ""


def native_binary(name: str) -> Path:
    """Path of the workspace binary ``name`` (debug build), building the workspace if needed."""
    why = _build()
    if why:
        pytest.skip(why)
    path = TARGET / "debug" / name
    assert path.is_file(), f"{path} missing after the build"
    return path
