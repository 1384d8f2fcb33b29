"""The pilot's faces through the shipped ACL router (docs/semantics.md §8, issue 24 item 4): ``skinet goal`` and the
dashboard's goal box reach the pilot as the ``operator`` login, and say plainly that nobody answered when
they run as ``observer`` (the router drops the other logins' goal requests without a word).

No containers: the router is the Python wheel with ``docker/zenoh/router.json5``; the real pilot logs in as
``pilot``.  There is no monitor, so an accepted goal waits for one (``waiting for monitor``): what is
judged here is who reaches the pilot, not the driving (``tests/services/test_goal.py``)."""

from __future__ import annotations

import subprocess
import sys
import urllib.request
from collections.abc import Iterator

import pytest
import zenoh

from deploy_support import REPO, SYSTEM, Tokens, acl_router_config, free_port, login, passwords, wait_until
from services.pilot import start_pilot
from skinet.system.load import load_system, load_typemap

SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
REFUSED = ("no pilot answers on skinet/spot_arm/pilot/goal/observer: is `skinet run` or the pilot service running? "
           "(or the router refused user 'observer': only operator-role users may send goals)")


@pytest.fixture(scope="module")
def deployment() -> Iterator[tuple[str, object]]:
    """ACL router and the real pilot logged in as ``pilot``: (endpoint, pilot)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(acl_router_config(endpoint))
    session, reader = login(endpoint, "pilot"), login(endpoint, "observer")
    pilot = start_pilot(session, load_system(SYSTEM_FILE)[0], instance="p1", client="pilot",
                        typemap=load_typemap(SYSTEM_FILE), memory_limit=None)  # see tests/services/pilot_robot.py
    tokens = Tokens(reader)
    try:
        wait_until(lambda: bool(tokens.of("pilot")), 10, "the pilot's liveliness token")
        yield endpoint, pilot
    finally:
        tokens.close()
        pilot.close()
        for s in (reader, session, router):
            s.close()


def goal(endpoint: str, user: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skinet_cli.main", "goal", SYSTEM, *args, "-e", endpoint,
                           "--user", user, "--password", passwords()[user]], cwd=REPO, capture_output=True, text=True,
                          timeout=60)


def test_skinet_goal_reaches_the_pilot_as_operator_only(deployment) -> None:
    endpoint, pilot = deployment
    refused = goal(endpoint, "observer", "reach spot:Standing", "--drive")
    assert (refused.returncode, refused.stdout, refused.stderr) == (1, "", f"skinet: error: {REFUSED}\n")
    answered = goal(endpoint, "operator", "--pause")  # the pilot's own answer: nothing to pause
    assert (answered.returncode, answered.stderr) == (
        2, "pause rejected by the pilot: no goal is being followed: nothing to pause\n")
    assert pilot.status.goal_id == 0  # nothing the observer sent reached it


def test_the_goal_box_shows_the_routers_refusal_and_an_operators_goal_goes_through(deployment, tmp_path) -> None:
    from selenium.webdriver.common.by import By

    from tests.screenshot import Unavailable, chromium

    endpoint, pilot = deployment
    try:
        browser = chromium()
    except Unavailable as exc:
        pytest.skip(str(exc))
    procs = []
    try:
        for user in ("observer", "operator"):
            port = free_port()
            with (tmp_path / f"dashboard-{user}.log").open("w") as log:
                procs.append(subprocess.Popen(
                    [sys.executable, "-m", "services.dashboard", str(SYSTEM_FILE), "--port", str(port), "--wait", "0",
                     "-e", endpoint, "--user", user, "--password", passwords()[user]], cwd=REPO, stdout=log,
                    stderr=subprocess.STDOUT))
            url = f"http://127.0.0.1:{port}/"
            wait_until(lambda: _up(url), 20, f"the {user}'s dashboard")
            browser.get(url)
            wait_until(lambda: browser.execute_script(
                "return document.getElementById('pilot-panel').dataset.pilot") == "alive", 20, "the pilot seen alive")
            box = browser.find_element(By.ID, "goal-text")
            box.clear()
            box.send_keys("reach spot:Standing")
            browser.find_element(By.ID, "goal-start").click()
            if user == "observer":
                wait_until(lambda: browser.execute_script(
                    "return document.querySelector('#goal-error .message')?.textContent") == REFUSED, 20,
                    "the refusal in the box")
                assert pilot.status.goal_id == 0
            else:
                wait_until(lambda: pilot.status.goal_id == 1, 20, "the operator's goal accepted")
                wait_until(lambda: browser.execute_script(
                    "return document.querySelector('#pilot-status .pilot-state')?.dataset.state") ==
                    "waiting for monitor", 20, "the pilot's status on the page")
                assert browser.execute_script("return document.getElementById('goal-error').hidden")
                assert pilot.status.client == "operator"
    finally:
        browser.quit()
        for proc in procs:
            proc.terminate()
            proc.wait(10)


def _up(url: str) -> bool:
    try:
        with urllib.request.urlopen(url + "api/snapshot", timeout=1) as r:
            return r.status == 200
    except OSError:
        return False
