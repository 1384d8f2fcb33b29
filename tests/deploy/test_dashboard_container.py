"""The ``dashboard`` service of ``compose.yaml`` (onboard profile): published on the host's
loopback only, logged in as the read-only ``observer``, showing the containerised monitor
and asking its command check (docs/semantics.md §7).  The image is test_containers' (``$SKINET_TEST_IMAGE``,
default ``skinet-live:local``, built by ``docker/build.sh --local-base``)."""

from __future__ import annotations

import json
import os
import subprocess
import urllib.request
from collections.abc import Iterator

import pytest

from deploy_support import free_port, wait_until
from test_containers import Stack, image  # noqa: F401 (the image fixture)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def onboard(image: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Stack, int]]:
    """Router, monitor and dashboard of the onboard profile; yields the stack and the dashboard's host port."""
    port = free_port()
    env = {**os.environ, "COMPOSE_PROFILES": "onboard", "SKINET_IMAGE": image,
           "SKINET_ROUTER_PORT": f"127.0.0.1:{free_port()}", "SKINET_DASHBOARD_PORT": str(port)}
    s = Stack(f"skinet-dash-{os.getpid()}", env)
    try:
        s.compose("up", "-d", "--no-build", "router", "monitor", "dashboard", timeout=180)
        yield s, port
    finally:
        (tmp_path_factory.mktemp("compose") / "compose.log").write_text(s.logs())
        s.down()


def get(port: int, path: str) -> dict:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=3) as r:
        return json.load(r)


def test_dashboard_container_shows_the_monitor_and_checks(onboard: tuple[Stack, int]) -> None:
    stack, port = onboard

    def ready() -> bool:
        try:
            snap = get(port, "/api/snapshot")
        except OSError:
            return False
        return bool(snap["alive"].get("monitor")) and snap["state"] is not None and snap["unsafe"] is not None

    wait_until(ready, 90, "the dashboard showing the monitor")
    snap = get(port, "/api/snapshot")
    assert snap["system"] == "spot_arm" and snap["state"]["seq"] == 0
    assert [v["name"] for v in snap["verdicts"]["properties"]] == ["action_guard", "safety_guard"]
    # Neither bridge nor predictor in this stack: the monitor vouches for nothing (docs/semantics.md §7), and says so.
    assert {n: s["state"] for n, s in snap["state"]["sync"].items()} == {"spot": "syncing", "manipulator": "syncing"}
    reply = get(port, "/api/check?command=spot:init_power.start")
    assert (reply["ok"], reply["decision"], reply["enabled"], reply["state_stale"]) == (True, "warn", True, True)
    assert [r["constraint"] for r in reply["reasons"]] == ["state_unknown", "prediction_pending"]
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/static/app.js", timeout=3) as r:
        assert r.headers["Content-Type"].startswith("text/javascript")
    (container,) = stack.containers("dashboard")
    ports = subprocess.run(["docker", "port", container, "8080/tcp"], capture_output=True, text=True).stdout.split()
    assert ports == [f"127.0.0.1:{port}"]  # the host's loopback only
