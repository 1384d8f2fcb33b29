"""``skinet demo`` from any folder (issue 32, item 7): an editable install reads the checkout's files, and a
wheel ships them (``setup.py`` copies ``skillsets/`` and ``examples/nav2/`` into ``skinet_cli/demo_files``)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SKINET = Path(sys.executable).parent / "skinet"
FIRST = "unassisted"  # the first run's name in the table


def test_the_demo_runs_from_another_folder(tmp_path: Path) -> None:
    r = subprocess.run([str(SKINET), "demo", "--core"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert (r.returncode, r.stderr) == (0, ""), r.stderr
    assert "   mobile assisted " in r.stdout
    r = subprocess.run([str(SKINET), "demo", "--core", "nav2"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert (r.returncode, r.stderr) == (0, ""), r.stderr


def test_a_wheel_ships_the_demos_files_and_its_demo_runs_from_them(tmp_path: Path) -> None:
    source = tmp_path / "source"  # the tracked files a build reads, so that no build/ lands in the checkout
    for name in ("pyproject.toml", "setup.py", "README.md"):
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / name, source / name)
    for folder in ("skinet", "services", "skinet_cli", "skillsets", "examples"):
        shutil.copytree(REPO / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                        "--disable-pip-version-check", "-w", str(tmp_path / "dist"), str(source)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    wheel, = (tmp_path / "dist").glob("*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for shipped in ("skillsets/missions/unassisted.toml", "skillsets/spot_arm.toml", "skillsets/spot.rl",
                    "examples/nav2/missions/nav2_run.toml", "examples/nav2/nav2.binding.toml"):
        assert f"skinet_cli/demo_files/{shipped}" in names, shipped
    # Installed alone (no checkout beside it): the demo reads the files the wheel ships.
    target = tmp_path / "installed"
    zipfile.ZipFile(wheel).extractall(target)
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    r = subprocess.run([sys.executable, "-c", "from skinet_cli.demo import default_scenarios; "
                        "print(default_scenarios()[0])"], cwd=folder, capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(target)})
    assert (r.returncode, r.stdout) == (0, f"{target}/skinet_cli/demo_files/skillsets/missions/{FIRST}.toml\n"), r
    r = subprocess.run([sys.executable, "-m", "skinet_cli.main", "demo", "--core"], cwd=folder, capture_output=True,
                       text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(target)})
    assert (r.returncode, r.stderr) == (0, ""), r.stderr
