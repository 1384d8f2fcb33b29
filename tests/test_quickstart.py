"""The README's quickstart works as written (issue 27, item 5; issue 32, item 3): its two commands
and the one of "Try it live" are the Makefile's, ``make demo`` prints the paper's violations and
warnings, ``make live`` serves the dashboard it names, and ``make test`` is exactly what CI runs
(``.ci/run``; running it from here would run this test again, so its recipe is read with ``make -n``)."""

from __future__ import annotations

import os
import re
import subprocess
import threading
import time
import urllib.request
from pathlib import Path

from tests.loopback import free_port

REPO = Path(__file__).resolve().parents[1]


def quickstart(heading: str = "Quickstart") -> list[str]:
    """The commands of the first code block under the README's ``## heading``, comments removed."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme.split(f"\n## {heading}\n", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```sh\n(.*?)```", section, re.S)
    assert block is not None
    return [line.split("#", 1)[0].strip() for line in block[1].splitlines() if line.split("#", 1)[0].strip()]


def make(*args: str, timeout: float) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SKINET_", "MAKEFLAGS", "MFLAGS"))}
    return subprocess.run(["make", "--no-print-directory", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=timeout, env=env)


def test_the_quickstart_is_two_make_targets_and_live_a_third() -> None:
    assert quickstart() == ["make demo", "make test"]
    assert quickstart("Try it live") == ["make live"]


def test_make_test_is_what_ci_runs() -> None:
    assert (REPO / ".ci" / "run").read_text().rstrip().endswith("\nmake test")
    recipe = make("-n", "test", timeout=60)
    assert recipe.returncode == 0, recipe.stderr
    assert recipe.stdout.rstrip().splitlines()[-1].startswith(".venv/bin/python -m pytest -q -n auto")


def test_make_demo_plays_the_papers_mission() -> None:
    r = make("demo", timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "   violations: 3; action_guard at step 26; safety_guard at step 33; action_guard at step 38" in r.stdout
    assert ("   warnings heeded (commands considered, flagged, not issued): 2; spot:go_to_waypoint.start explicit "
            "for safety_guard at step 29; manipulator:arm_ready.start explicit for action_guard at step 36"
            ) in r.stdout


def test_make_live_serves_the_dashboard_it_names() -> None:
    port = free_port()
    seen: dict[str, object] = {}
    proc = subprocess.Popen(["make", "--no-print-directory", "live", f"PORT={port}",
                             "LIVE_ARGS=--speed 20 --linger 5"], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            env={k: v for k, v in os.environ.items() if not k.startswith("SKINET_")})
    url = f"http://127.0.0.1:{port}/"

    def page() -> None:  # while the run plays: the page it printed answers
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and "page" not in seen:
            try:
                with urllib.request.urlopen(url, timeout=2) as r:
                    seen["page"] = r.read().decode()
            except OSError:
                time.sleep(0.2)

    reader = threading.Thread(target=page, daemon=True)
    reader.start()
    try:
        out, _ = proc.communicate(timeout=300)
    finally:
        proc.kill()
    reader.join(5)
    assert proc.returncode == 0, out[-3000:]
    assert url in out
    assert "violations: 3; action_guard at step 26; safety_guard at step 33; action_guard at step 38" in out
    assert "SkiNet Live" in str(seen.get("page", "")), out[-3000:]
