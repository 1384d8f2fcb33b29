"""Every example of ``skinet --help`` works as written (issue 27, item 2).

The examples are read from the help text itself: each line of the epilog that starts with
``skinet`` or ``python -m``, in sections separated by blank lines.  They run in order, as real
processes, in a temporary folder that holds a link to ``skillsets/`` and is also ``$HOME`` (the
router's secrets; ``~`` in the examples, as a shell expands it).  Two liberties, both needed to
run beside other tests: the fixed ports (7447, 7448, 8080, 8081) become free ones, and
``skinet`` and ``python`` are this interpreter's.

A command that ends must exit 0 (``skinet check``: 0, 3 or 4, its decision).  A command that
keeps running (run, router, bridge, watch, record, dashboard) must show that it is ready, and
exits 0 when stopped with SIGTERM at the end of its section (``skinet record`` when the
``skinet timeline`` that reads its log comes).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path

import pytest

from skinet.mission.scenario import parse_scenario
from skinet_cli.main import EPILOG
from tests.processes import Watched
from tests.services.conftest import free_port

ROOT = Path(__file__).resolve().parents[2]
PORTS = ("7447", "7448", "8080", "8081")
MISSION = ROOT / "skillsets" / "missions" / "unassisted.toml"
MISSION_STEPS = sum(s.transition is not None for s in parse_scenario(MISSION.read_text(), str(MISSION)).steps)


def sections(epilog: str) -> list[list[str]]:
    """The example commands of the epilog, per section."""
    out: list[list[str]] = [[]]
    for line in epilog.splitlines():
        if not line.strip():
            out.append([])
        elif re.match(r"  (skinet|python -m) ", line):
            out[-1].append(line.strip())
    return [s for s in out if s]


def http_ok(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=1) as r:
            return r.status == 200
    except OSError:
        return False


def snapshot(url: str) -> dict:
    with urllib.request.urlopen(url + "api/snapshot", timeout=2) as r:
        return json.loads(r.read())


def test_help_has_the_examples_of_every_kind() -> None:
    found = sections(EPILOG)
    assert len(found) == 3
    assert [len(s) for s in found] == [9, 7, 3]
    assert '{"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"}, ' \
           '"running": ["teleop"]}}' in EPILOG  # a state the robot can be in (teleop.inv.powered holds)


def test_every_help_example_works_as_written(tmp_path: Path) -> None:
    (tmp_path / "skillsets").symlink_to(ROOT / "skillsets")
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SKINET_")}
    env["HOME"] = str(tmp_path)
    ports = {p: str(free_port()) for p in PORTS}
    background: list[tuple[str, Watched]] = []
    try:
        for section in sections(EPILOG):
            for example in section:
                text = example
                for fixed, free in ports.items():
                    text = text.replace(fixed, free)
                words = shlex.split(text)
                words = [str(tmp_path) + w[1:] if w.startswith("~/") else w for w in words]
                argv = ([sys.executable, "-m", "skinet_cli.main", *words[1:]] if words[0] == "skinet"
                        else [sys.executable, *words[1:]])
                name = " ".join(words[:2]) if words[0] == "skinet" else " ".join(words[:3])
                if name == "skinet timeline":  # its log is finished when the recorder stops
                    for other, proc in background:
                        if other == "skinet record":
                            assert proc.stop() == 0, proc.text
                            assert re.search(r"skinet record: [1-9]\d* messages written to run.jsonl", proc.text)
                if name in READY:
                    proc = Watched(argv, tmp_path, env)
                    background.append((name, proc))
                    READY[name](proc, words)
                    continue
                done = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
                allowed = (0, 3, 4) if name == "skinet check" else (0,)
                assert done.returncode in allowed, f"{example}\n{done.stdout}\n{done.stderr}"
                CHECK.get(name, lambda _d, _w: None)(done, words)
            for name, proc in reversed(background):
                code = proc.stop()
                assert code == 0, f"{name} exited {code} on SIGTERM:\n{proc.text}"
                if name == "skinet watch":  # in a pipe: one line per step, up to the mission's last
                    # (and one per set of sync states while the monitor waits for the bridge: docs/semantics.md §7)
                    lines = re.findall(r"^\[(\d+)\] .*$", proc.text, re.M)
                    steps = [int(m) for m in re.findall(r"^\[(\d+)\] ", proc.text, re.M)]
                    live = [int(m) for m in re.findall(r"^\[(\d+)\] (?!.*STATE STALE).*$", proc.text, re.M)]
                    assert lines and steps == sorted(steps) and live == sorted(set(live)), proc.text
                    # The simulator's managers appear with its first steps: when those come before the monitor
                    # has synced, its resync answer covers them and makes one step of them (docs/semantics.md §7).
                    covered = re.findall(r"^\[(\d+)\] \w+:resync#(\d+) ", proc.text, re.M)
                    assert steps[-1] == MISSION_STEPS or (covered and steps[-1] < MISSION_STEPS), proc.text
                    last = [s.transition for s in parse_scenario(MISSION.read_text(), str(MISSION)).steps
                            if s.transition is not None][-1]
                    assert re.search(rf"^\[{steps[-1]}\] \w+:{re.escape(last)}#\d+ ", proc.text, re.M), proc.text
            background.clear()
    finally:
        for _, proc in background:
            proc.stop()
    assert (tmp_path / "spot.net").read_text().startswith("net spot")
    assert (tmp_path / "run.png").stat().st_size > 10_000


def _dashboard_ready(proc: Watched, words: list[str], flag: str) -> None:
    port = words[words.index(flag) + 1]
    proc.wait_for(lambda _: http_ok(f"http://127.0.0.1:{port}/api/snapshot"), "serving the dashboard")
    proc.wait_for(lambda _: bool(snapshot(f"http://127.0.0.1:{port}/").get("alive", {}).get("monitor")),
                  "showing a live monitor")


def _run_ready(proc: Watched, words: list[str]) -> None:
    proc.wait_for(lambda t: "connect with:" in t, "ready")
    if "--dashboard" in words:
        _dashboard_ready(proc, words, "--dashboard")


READY: dict[str, Callable[[Watched, list[str]], None]] = {
    "skinet run": _run_ready,
    "skinet router": lambda p, _w: p.wait_for(lambda t: "zenoh router " in t, "listening"),
    "python -m services.bridge_ros2": lambda p, _w: p.wait_for(lambda t: "bridging the managers of spot_arm" in t,
                                                                "bridging"),
    "skinet watch": lambda p, _w: p.wait_for(lambda t: re.search(r"^\[\d+\] ", t, re.M) is not None,
                                             "showing a step"),
    "skinet record": lambda p, _w: p.wait_for(lambda t: "recording skinet/spot_arm/**" in t, "recording"),
    "skinet dashboard": lambda p, w: _dashboard_ready(p, w, "--port"),
}

CHECK: dict[str, Callable[[subprocess.CompletedProcess, list[str]], None]] = {
    "skinet demo": lambda d, _w: d.stdout.count("\n== ") + d.stdout.startswith("== ") == 6 or pytest.fail(d.stdout),
    "python -m services.simulator": lambda d, _w: f"step {MISSION_STEPS:>3} " in d.stdout or pytest.fail(d.stdout),
    "skinet check": lambda d, _w: d.stdout.startswith("spot:teleop.start: ") or pytest.fail(d.stdout + d.stderr),
}
