"""The SKINET_* environment variables (issue 27, item 1): a name nothing reads, or a bad value,
is refused with one line before any command or service starts; the table of variables
(services/common/environment.py) names every one the repository mentions."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import services.predictor.__main__ as predictor_main
from skinet_cli.main import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
SPOT = str(ROOT / "skillsets" / "spot.rl")


def _clean_env(**extra: str) -> dict[str, str]:
    return {**{k: v for k, v in os.environ.items() if not k.startswith("SKINET_")}, **extra}


def test_every_variable_the_repository_names_is_in_the_table() -> None:
    from services.common.environment import VARIABLES

    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    named: set[str] = set()
    for name in files:
        path = ROOT / name
        if path.suffix in (".png", ".mcap") or not path.is_file() or path == Path(__file__):
            continue  # this file names misspelt variables on purpose
        for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
            if "unknown environment variable" not in line:  # an example of the error names a misspelt one
                named |= set(re.findall(r"\bSKINET_[A-Z0-9_]*[A-Z0-9]\b", line))
    named.discard("SKINET_ZENOH")  # "SKINET_ZENOH_*" in prose
    assert sorted(named - set(VARIABLES)) == []
    assert sorted(set(VARIABLES) - named) == []


@pytest.mark.parametrize(("name", "value", "message"), [
    ("SKINET_ZENOH_CONECT", "tcp/127.0.0.1:7447",
     "unknown environment variable SKINET_ZENOH_CONECT: nothing reads it (candidates: SKINET_ZENOH_CONNECT)"),
    ("SKINET_SYSTME", "skillsets/spot_arm.toml",
     "unknown environment variable SKINET_SYSTME: nothing reads it (candidates: SKINET_SYSTEM)"),
    ("SKINET_FOO_BAR", "1",
     "unknown environment variable SKINET_FOO_BAR: nothing reads it (docs/deployment.md lists the variables)"),
    ("SKINET_ZENOH_SCOUTING", "maybe", "environment variable SKINET_ZENOH_SCOUTING: expected 1 or 0 (or true, "
     "false, yes, no, on, off), got 'maybe'"),
    ("SKINET_ZENOH_CONNECT_TIMEOUT", "soon", "environment variable SKINET_ZENOH_CONNECT_TIMEOUT: expected a number "
     "of seconds >= 0, or -1 (forever), got 'soon'"),
    ("SKINET_PREDICTORS", "two", "environment variable SKINET_PREDICTORS: expected an integer >= 0, got 'two'"),
    ("SKINET_ROUTER_PORT", "0.0.0.0:", "environment variable SKINET_ROUTER_PORT: expected PORT or HOST:PORT with a "
     "port from 1 to 65535, e.g. 127.0.0.1:7447, got '0.0.0.0:'"),
    ("SKINET_ONBOARD_ENDPOINT", "robot:7447", "environment variable SKINET_ONBOARD_ENDPOINT: an endpoint is "
     "PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447, got 'robot:7447'"),
    ("SKINET_PREDICT_BUDGET", "0.01", "environment variable SKINET_PREDICT_BUDGET: expected a number of seconds from "
     "0.05 (the predictor's minimum budget) to 86400 (one day), got '0.01'"),
    ("SKINET_PREDICT_BUDGET", "1e308", "environment variable SKINET_PREDICT_BUDGET: expected a number of seconds from "
     "0.05 (the predictor's minimum budget) to 86400 (one day), got '1e308'"),
    ("SKINET_INCLUDE_ROOT", "/no/such/folder", "environment variable SKINET_INCLUDE_ROOT: expected an existing "
     "folder, got '/no/such/folder'"),
    ("SKINET_FAILURE_RATE", "1.5", "environment variable SKINET_FAILURE_RATE: expected a probability from 0 to 1, "
     "got '1.5'"),
    ("SKINET_SKILL_DURATION", "-1", "environment variable SKINET_SKILL_DURATION: expected a number of seconds >= 0, "
     "got '-1'"),
])
def test_unknown_names_and_bad_values_are_refused(name: str, value: str, message: str,
                                                  capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(name, value)
    assert main(["parse", SPOT]) == 1
    assert capsys.readouterr() == ("", f"skinet: error: {message}\n")
    assert predictor_main.main(["--workers", "1"]) == 1
    assert capsys.readouterr() == ("", f"python -m services.predictor: error: {message}\n")


def test_known_names_pass() -> None:
    from services.common.environment import check_environment

    check_environment({"SKINET_ZENOH_SCOUTING": "0", "SKINET_ZENOH_CONNECT_TIMEOUT": "-1", "SKINET_PREDICTORS": "4",
                       "SKINET_ROUTER_PORT": "127.0.0.1:7447", "SKINET_HUB_PORT": "7448",
                       "SKINET_ONBOARD_ENDPOINT": "tls/robot.example:7447", "SKINET_START_DELAY": "0",
                       "SKINET_TEST_IMAGE": "skinet-live:x", "PATH": "/bin", "SKINETX": "not ours"})


@pytest.mark.parametrize(("value", "on"), [("1", True), ("true", True), ("0", False), ("false", False), ("", False)])
def test_scouting_variable_means_what_it_says(value: str, on: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """``SKINET_ZENOH_SCOUTING=false`` used to turn multicast scouting on (any value but "" and "0" did)."""
    monkeypatch.setenv("SKINET_ZENOH_SCOUTING", value)
    args = build_parser("watch").parse_args(["watch", "spot_arm"])
    assert args.multicast_scouting is on


def test_the_simulated_robots_variables_are_the_defaults_of_its_options(monkeypatch: pytest.MonkeyPatch) -> None:
    """SKINET_SKILL_DURATION and SKINET_FAILURE_RATE give --skill-duration and --failure-rate when they are not
    given (skinet run --simulate, python -m services.simulator --self-ending)."""
    from services.common.options import self_ending_options

    run = ["run", "skillsets/spot_arm.toml", "--simulate"]
    assert self_ending_options(build_parser("run").parse_args(run), "--simulate", True) == (1.0, 0.0, 0)
    monkeypatch.setenv("SKINET_SKILL_DURATION", "2.5")
    monkeypatch.setenv("SKINET_FAILURE_RATE", "0.25")
    assert self_ending_options(build_parser("run").parse_args(run), "--simulate", True) == (2.5, 0.25, 0)
    args = build_parser("run").parse_args([*run, "--failure-rate", "0", "--seed", "7"])
    assert self_ending_options(args, "--simulate", True) == (2.5, 0.0, 7)


def test_entry_points_refuse_a_misspelt_variable() -> None:
    for argv, prog in ((["-m", "skinet_cli.main", "parse", SPOT], "skinet"),
                       (["-m", "services.monitor", str(ROOT / "skillsets" / "spot_arm.toml")],
                        "python -m services.monitor")):
        done = subprocess.run([sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=60,
                              env=_clean_env(SKINET_ZENOH_MOD="client"))
        assert (done.returncode, done.stdout, done.stderr) == (
            1, "", f"{prog}: error: unknown environment variable SKINET_ZENOH_MOD: nothing reads it "
                   "(candidates: SKINET_ZENOH_MODE)\n")


def test_container_entry_point_refuses_a_bad_value(tmp_path: Path) -> None:
    """docker/entrypoint.sh used to fail with a traceback on SKINET_ZENOH_CONNECT_TIMEOUT=soon."""
    env = _clean_env(SKINET_ZENOH_CONNECT_TIMEOUT="soon", SKINET_ZENOH_MODE="client", TMPDIR=str(tmp_path),
                     PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    done = subprocess.run(["sh", str(ROOT / "docker" / "entrypoint.sh"), "predictor"], cwd=ROOT, capture_output=True,
                          text=True, timeout=60, env=env)
    assert (done.returncode, done.stdout, done.stderr) == (
        1, "", "skinet-entrypoint: error: environment variable SKINET_ZENOH_CONNECT_TIMEOUT: expected a number of "
               "seconds >= 0, or -1 (forever), got 'soon'\n")
