"""The set-up commands: a quiet install, and a CI entry point that fails when nothing is collected (issue 13)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_editable_install_prints_no_warning(tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    # The Makefile's own command, without the dependencies (already in this venv's site-packages).
    r = subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install",
                        "--quiet", "--no-deps", "--disable-pip-version-check", "-e", str(REPO)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout + r.stderr == ""
    pth = list((venv / "lib").glob("python3*/site-packages/__editable__.skinet_live-*.pth"))
    assert [p.read_text().strip() for p in pth] == [str(REPO)]


def test_ci_fails_when_pytest_collects_nothing() -> None:
    """``.ci/run`` is ``make test``: pytest's exit status 5 (no test ran) must fail it, workers or not."""
    r = subprocess.run(["bash", str(REPO / ".ci" / "run")], capture_output=True, text=True, timeout=600,
                       env={**os.environ, "PYTEST_ADDOPTS": "-k no_test_has_this_name tests/test_setup.py"})
    assert r.returncode != 0
    assert "no tests ran" in r.stdout and "Error 5" in r.stderr, r.stdout[-2000:] + r.stderr[-2000:]


def _groups(*args: str) -> list[tuple[str, str]]:
    """(module, xdist group) of each test ``make test``'s options would hand out with ``args``."""
    r = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "--dist", "loadgroup", "-v", "-p",
                        "no:cacheprovider", "--setup-plan", *args], cwd=REPO, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    # The workers name a grouped test ``NODEID@GROUP``; --setup-plan runs neither fixtures nor tests.  A test
    # skipped at collection (no corpus beside a fresh clone) has a second line, ``[gwN] SKIPPED NODEID``.
    ids = [line.strip() for line in r.stdout.splitlines() if "::" in line and not line.startswith("[gw")]
    return [(i.split("::")[0], i.rsplit("@", 1)[1] if "@" in i else "") for i in ids]


def test_slow_tests_are_grouped() -> None:
    """``make test``'s ``--dist loadgroup`` keeps each slow module on one worker (see conftest.py).

    Their module-scoped stacks are set up once that way; pytest 9.2 broke the grouping silently
    (pytest-xdist#1386), so the versions in pyproject.toml are checked here.  The modules that time
    services under load share one group.
    """
    files = ["tests/net/test_promela.py", "tests/deploy/test_rust_client.py", "tests/deploy/test_fleet.py"]
    slow = _groups("-m", "slow", *files)
    assert len(slow) == 9 and dict(slow) == {f: f for f in files}, slow
    timed = _groups("tests/deploy/test_containers.py", "tests/deploy/test_rate_limit.py")
    assert len(timed) == 9 and {g for _, g in timed} == {"timed"}, timed
