"""The ``SKINET_*`` environment variables: every one the project reads, checked before a command starts.

Compose passes settings as environment variables, and a misspelt name
(a missing letter in ``SKINET_ZENOH_CONNECT``) would be ignored in silence, the service then running
with its default.  So every ``skinet`` command and every ``python -m services.*``
refuses, with one line, a ``SKINET_`` variable that nothing reads (with the
close names) and a bad value of a variable that no option checks (those read
as an option's default are checked by the option, which names the variable).
The table also names what reads each variable: `tests/test_environment.py`
fails when a ``SKINET_`` name appears in the repository without a row here.
Cost: one pass over the environment.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from skinet.closenames import close_names
from skinet.errors import SkinetError

PREFIX = "SKINET_"


class EnvironmentVariableError(SkinetError):
    """A ``SKINET_`` variable that nothing reads, or a bad value (one line)."""


def _flag(text: str) -> bool:
    if text.strip().lower() in ("", "0", "false", "no", "off"):
        return False
    if text.strip().lower() in ("1", "true", "yes", "on"):
        return True
    raise ValueError("expected 1 or 0 (or true, false, yes, no, on, off)")


def _seconds_or_forever(text: str) -> float:
    return _number(text, lambda v: (0 <= v < float("inf") or v == -1), "expected a number of seconds >= 0, or -1 (forever)")


def _count(text: str) -> int:
    if not text.strip().isdigit():
        raise ValueError("expected an integer >= 0")
    return int(text)


def _number(text: str, ok: Callable[[float], bool], expected: str) -> float:
    """``text`` as a float that ``ok`` accepts, else ValueError(``expected``) (NaN and words are never ok)."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(expected) from None
    if not ok(value):
        raise ValueError(expected)
    return value


def _positive_seconds(text: str) -> float:
    return _number(text, lambda v: 0 < v < float("inf"), "expected a number of seconds > 0")


def _budget(text: str) -> float:
    from skinet.wire.limits import MAX_BUDGET, MIN_BUDGET

    return _number(text, lambda v: MIN_BUDGET <= v <= MAX_BUDGET,
                   f"expected a number of seconds from {MIN_BUDGET:g} (the predictor's minimum budget) to "
                   f"{MAX_BUDGET:g} (one day)")


def _probability(text: str) -> float:
    return _number(text, lambda v: 0 <= v <= 1, "expected a probability from 0 to 1")


def _folder(text: str) -> str:
    if not os.path.isdir(text):
        raise ValueError("expected an existing folder")
    return text


def _seconds(text: str) -> float:
    return _number(text, lambda v: 0 <= v < float("inf"), "expected a number of seconds >= 0")


def _published_port(text: str) -> str:
    """Compose's ``[HOST:]PORT`` of a published port."""
    m = re.fullmatch(r"(?:(?:\[[0-9A-Fa-f:.]+\]|[^:\[\]]+):)?(\d+)", text.strip())
    if m is None or not 0 < int(m.group(1)) <= 65535:
        raise ValueError("expected PORT or HOST:PORT with a port from 1 to 65535, e.g. 127.0.0.1:7447")
    return text


def _endpoint(text: str) -> str:
    from services.common.endpoints import ZenohSetupError, check_endpoint

    try:
        return check_endpoint(text, "")
    except ZenohSetupError as exc:
        raise ValueError(str(exc).split(": ", 1)[1]) from None


@dataclass(frozen=True)
class Variable:
    read_by: str
    check: Callable[[str], object] | None = None  # None: free text, or checked by the option it is the default of


VARIABLES: dict[str, Variable] = {
    # Zenoh sessions (services/common/zenoh_config.py, docker/entrypoint.sh)
    "SKINET_ZENOH_MODE": Variable("--mode of every command and service"),
    "SKINET_ZENOH_CONNECT": Variable("--connect of every command and service"),
    "SKINET_ZENOH_LISTEN": Variable("--listen of every command and service"),
    "SKINET_ZENOH_CONFIG": Variable("--zenoh-config of every command and service"),
    "SKINET_ZENOH_SCOUTING": Variable("--multicast-scouting of every command and service", _flag),
    "SKINET_ZENOH_USER": Variable("--user of every command and service"),
    "SKINET_ZENOH_PASSWORD": Variable("--password of every command and service"),
    "SKINET_ZENOH_PASSWORD_FILE": Variable("--password-file of every command and service"),
    "SKINET_ZENOH_CONNECT_TIMEOUT": Variable("docker/entrypoint.sh: seconds a client waits for its router",
                                             _seconds_or_forever),
    "SKINET_SECRETS": Variable("skinet router, skinet fleet, skinet client-config, python -m services.secrets, "
                               "docker/entrypoint.sh, compose.yaml: the secrets folder (compose: the vault)"),
    "SKINET_TLS_HOSTNAMES": Variable("skinet router, python -m services.secrets: names in the certificates they make"),
    "SKINET_FLEET_ROBOTS": Variable("skinet router --robots, compose.yaml"),
    "SKINET_HANDED_SECRETS": Variable("skinet router --handed, compose.yaml: the router's hand-out, read-only"),
    # services
    "SKINET_LOG_LEVEL": Variable("--log-level of the services, compose.yaml"),
    "SKINET_INSTANCE": Variable("--instance of the bridge, the predictor and the pilot"),
    "SKINET_CHECK_POLICY": Variable("--check-policy of the monitor and skinet run, compose.yaml"),
    "SKINET_CHECK_RATE_LIMIT": Variable("--check-rate-limit of the monitor and skinet run"),
    "SKINET_LOST_AFTER": Variable("--lost-after of the monitor and skinet run, compose.yaml"),
    "SKINET_STATUS_POLL": Variable("--status-poll of the bridge; the period of a bridge skinet run or the embedded "
                                   "chain starts, compose.yaml"),
    "SKINET_RATE_LIMIT": Variable("--rate-limit of the predictor and skinet run"),
    "SKINET_ROS_NAMESPACE": Variable("--namespace of the bridge, the pilot and skinet run, compose.yaml"),
    "SKINET_SPEED": Variable("--speed of the simulator, compose.yaml"),
    "SKINET_SKILL_DURATION": Variable("--skill-duration of the simulator --self-ending and skinet run --simulate",
                                      _seconds),
    "SKINET_FAILURE_RATE": Variable("--failure-rate of the simulator --self-ending and skinet run --simulate",
                                    _probability),
    "SKINET_DASHBOARD_HOST": Variable("--host of the dashboard"),
    "SKINET_DASHBOARD_PORT": Variable("--port of the dashboard, compose.yaml (the host port)"),
    "SKINET_DASHBOARD_FOXGLOVE": Variable("--foxglove of the dashboard: also serve Foxglove on this port"),
    "SKINET_FOXGLOVE_HOST": Variable("--host of skinet foxglove"),
    "SKINET_FOXGLOVE_PORT": Variable("--port of skinet foxglove, compose.yaml (the dashboard's Foxglove host port)"),
    "SKINET_FOXGLOVE": Variable("compose.yaml: the dashboard container's Foxglove port inside (8765; unset: none)"),
    "SKINET_DASHBOARD_GOAL_USER": Variable("--goal-user of the dashboard, compose.yaml: its goal box's login"),
    "SKINET_DASHBOARD_GOAL_SECRETS": Variable("--goal-secrets of the dashboard: the goal login's secrets"),
    "SKINET_TRACEBACK": Variable("skinet: print the traceback of an internal error"),
    "SKINET_INCLUDE_ROOT": Variable("skinet.system.load: the folder included model files must stay in (default: the "
                                    "including model's own)", _folder),
    # compose.yaml, docker/*.sh
    "SKINET_IMAGE": Variable("compose.yaml, docker/build.sh: the image"),
    "SKINET_BASE_IMAGE": Variable("compose.yaml, docker/build.sh: the base image"),
    "SKINET_BASE_TAG": Variable("docker/base-image.sh: the tag of the base image it builds"),
    "SKINET_CACHE": Variable("docker/build.sh: the wheel cache"),
    "SKINET_SKILLSETS": Variable("compose.yaml: the host folder of models and scenarios"),
    "SKINET_SYSTEM": Variable("compose.yaml: the system file of the bridge, monitor and dashboard"),
    "SKINET_ZENOH_DIR": Variable("compose.yaml: the host folder of router.json5"),
    "SKINET_PREDICTOR_SECRETS": Variable("compose.yaml: the predictors' own secrets (off-board: a host folder)"),
    "SKINET_ROUTER_PORT": Variable("compose.yaml: the router's published port", _published_port),
    "SKINET_HUB_PORT": Variable("compose.yaml: the hub's published port", _published_port),
    "SKINET_DASHBOARD_BIND": Variable("compose.yaml: the address the dashboard's port is published on"),
    "SKINET_ONBOARD_ENDPOINT": Variable("compose.yaml: where off-board predictors connect", _endpoint),
    "SKINET_PREDICTORS": Variable("compose.yaml: predictor replicas", _count),
    "SKINET_PREDICT_BUDGET": Variable("compose.yaml: the monitor's --budget", _budget),
    "SKINET_SCENARIO": Variable("compose.yaml: the simulator's scenario"),
    "SKINET_START_DELAY": Variable("compose.yaml: the simulator's --start-delay", _seconds),
    # tests
    "SKINET_TEST_IMAGE": Variable("tests/deploy: the image under test"),
    "SKINET_TEST_RUST_LOG": Variable("tests/deploy: RUST_LOG of the Rust client"),
    "SKINET_SCREENSHOTS": Variable("tests/services/test_dashboard.py: a folder for screenshots"),
}


def check_environment(environ: Mapping[str, str] | None = None) -> None:
    """Raise :class:`EnvironmentVariableError` on the first ``SKINET_`` variable nothing reads, or bad value."""
    environ = os.environ if environ is None else environ
    for name in sorted(n for n in environ if n.startswith(PREFIX)):
        variable = VARIABLES.get(name)
        if variable is None:
            # Every name shares the prefix, and many share SKINET_ZENOH_: compare the rest, closely.
            rest = [v[len(PREFIX):] for v in sorted(VARIABLES)]
            close = [PREFIX + n for n in close_names(name[len(PREFIX):], rest, cutoff=0.8)]
            hint = f"candidates: {', '.join(close)}" if close else "docs/deployment.md lists the variables"
            raise EnvironmentVariableError(f"unknown environment variable {name}: nothing reads it ({hint})")
        if variable.check is not None:
            try:
                variable.check(environ[name])
            except ValueError as exc:
                raise EnvironmentVariableError(f"environment variable {name}: {exc}, got '{environ[name]}'") from None


def flag(name: str) -> bool:
    """A yes/no variable (``SKINET_ZENOH_SCOUTING``), false when unset or bad: a bad value is refused by
    :func:`check_environment`, which every command runs before it reads its arguments' values."""
    try:
        return _flag(os.environ.get(name, ""))
    except ValueError:
        return False
