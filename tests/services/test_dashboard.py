"""The live web dashboard in a real browser (docs/semantics.md §7; docs/mission.md acceptance on the page).

Headless Chromium from Debian's packages (``chromium``, ``chromium-driver``;
``scripts/install-test-deps.sh`` installs them) driven by selenium.  The
dashboard runs as its own process (``python -m services.dashboard``), a client
of a loopback router; the mission is played by the simulated managers through
the bridge, the monitor and a predictor on another client session.  After each
step of a run the page must show what the operator would see then.
Screenshots go to the test's temporary folder (and ``$SKINET_SCREENSHOTS`` when
set).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from chains.chain import run_any_chain
from services.dashboard.board import Board
from services.monitor import start_monitor
from skinet.system.load import load_system
from skinet.files.read import read_text
from skinet.mission.scenario import StepRecord, parse_scenario
from skinet.wire.messages import LiveState, PilotStatus, PropertyVerdict, UnsafeReport, Verdicts
from tests.services.conftest import REPO, client_args, free_port, open_client, open_router
from tests.services.test_divergences import TEN
from tests.services.test_monitor import Events

SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
MISSIONS = REPO / "skillsets" / "missions"
# docs/mission.md in `skinet demo` numbering: (property, step, the step's command).
VIOLATIONS = [("action_guard", 26, "spot:teleop.start"), ("safety_guard", 33, "spot:go_to_waypoint.start"),
              ("action_guard", 38, "manipulator:arm_ready.start")]
WARNINGS = [(29, "spot", "go_to_waypoint.start", "safety_guard"), (36, "manipulator", "arm_ready.start", "action_guard")]


# -- fixtures -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    """Headless Chromium (tests/screenshot.py's); skipped with the reason when Chromium or selenium is missing."""
    from tests.screenshot import Unavailable, chromium

    try:
        driver = chromium()
    except Unavailable as exc:
        pytest.skip(str(exc))
    try:
        yield driver
    finally:
        driver.quit()


def wait_http(url: str, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(url, timeout=1) as r:
                if r.status == 200:
                    return
        except OSError:
            pass
        if time.monotonic() > deadline:
            pytest.fail(f"{url} did not answer within {timeout} s")
        time.sleep(0.1)


@pytest.fixture
def dashboard(spawn: Callable, router: str) -> Callable[..., str]:
    """Starts ``python -m services.dashboard`` on a free port; returns its URL."""
    def start(*extra: str, port: int | None = None, system: Path = SYSTEM_FILE) -> str:
        port = port or free_port()
        spawn("services.dashboard", str(system), "--port", str(port), "--wait", "1", *client_args(router), *extra)
        url = f"http://127.0.0.1:{port}/"
        wait_http(url + "api/snapshot")
        return url
    return start


def until(driver, predicate: Callable[[object], object], what: str, timeout: float = 20.0) -> object:
    from selenium.common.exceptions import TimeoutException
    from selenium.webdriver.support.ui import WebDriverWait

    try:
        return WebDriverWait(driver, timeout, poll_frequency=0.02).until(predicate)
    except TimeoutException:
        pytest.fail(f"the page never showed {what}")


def css(driver, selector: str) -> list[dict[str, str]]:
    """The elements matching ``selector``: their attributes and ``text``, read in one script
    (the page redraws its panels, so element handles go stale)."""
    return driver.execute_script(
        "return [...document.querySelectorAll(arguments[0])].map((e) => Object.assign("
        "Object.fromEntries([...e.attributes].map((a) => [a.name, a.value])), {text: e.textContent}))", selector)


def screenshot(driver, tmp_path: Path, name: str, element: str | None = None) -> Path:
    """The page (or the element of id ``element``) as ``name`` in ``tmp_path`` (and ``$SKINET_SCREENSHOTS``)."""
    path = tmp_path / name
    if element is None:
        driver.save_screenshot(str(path))
    else:
        from selenium.webdriver.common.by import By

        driver.find_element(By.ID, element).screenshot(str(path))
    if os.environ.get("SKINET_SCREENSHOTS"):
        folder = Path(os.environ["SKINET_SCREENSHOTS"])
        folder.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, folder / name)
    print(f"screenshot: {path}")
    return path


def play(run: str | Path, router: str, on_record: Callable[[StepRecord], None] | None = None,
         **options: Any) -> list[StepRecord]:
    """The mission ``run`` (a name in skillsets/missions, or a scenario file) through the whole chain (simulator,
    bridge, monitor, predictor; a bound system's through its bindings) on a client of ``router``; ``options`` are
    the chain's."""
    path = run if isinstance(run, Path) else MISSIONS / f"{run}.toml"
    scenario = parse_scenario(read_text(path), str(path))
    system_file = path.parent / scenario.system
    system, _ = load_system(system_file)
    session = open_client(router)
    try:
        return run_any_chain(system, system_file, scenario, session=session, on_record=on_record, **options)
    finally:
        session.close()


# -- the paper's mission on the page -----------------------------------------------------


def test_unassisted_run_shows_the_three_violations_at_their_steps(browser, dashboard, router, tmp_path) -> None:
    browser.get(dashboard())
    until(browser, lambda d: css(d, "#status[data-connected=true]"), "the live status")
    shown: list[tuple[str, int, str]] = []

    def after(record: StepRecord) -> None:
        expected = [v for v in VIOLATIONS if v[1] <= record.index]
        until(browser, lambda d: len(css(d, "#violations li[data-property]")) == len(expected),
              f"{len(expected)} violation(s) after step {record.index}")
        if record.violations:
            items = css(browser, "#violations li[data-property]")
            prop, event = items[-1]["data-property"], items[-1]["data-event"]
            shown.append((prop, record.index, event.split("#")[0]))
            row = css(browser, f"#properties tr[data-property={prop}]")[0]
            assert row["data-holds"] == "false" and "VIOLATED" in row["text"]
        if record.index == VIOLATIONS[-1][1] + 2:
            screenshot(browser, tmp_path, "dashboard-unassisted.png")

    records = play("unassisted", router, after)
    assert shown == VIOLATIONS
    assert [(p, r.index) for r in records for p in r.violations] == [(p, i) for p, i, _ in VIOLATIONS]
    # The timeline shows the three onsets; the step counter is the monitor's last step.
    labels = [e["text"] for e in css(browser, "#timeline .violation-label")]
    assert [label.split(" ")[0] for label in labels] == [p for p, _, _ in VIOLATIONS]
    assert css(browser, "#timeline .skill-bar") and css(browser, "#timeline .violated-bar")
    assert "fresh" in css(browser, "#prediction")[0]["text"]
    assert css(browser, "#state-space tr[data-field=markings] td")[0]["text"].isdigit()


def test_assisted_run_shows_the_two_warnings_before_the_commands(browser, dashboard, router, tmp_path) -> None:
    browser.get(dashboard())
    until(browser, lambda d: css(d, "#status[data-connected=true]"), "the live status")
    seen: list[tuple[int, str, str, str, str]] = []

    def after(record: StepRecord) -> None:
        for index, skillset, transition, prop in WARNINGS:
            if record.index != index or record.step.consider is None:  # a considered command shares its number
                continue
            selector = (f"#unsafe .group[data-skillset={skillset}] tr[data-transition='{transition}']"
                        f"[data-property={prop}]")
            rows = until(browser, lambda d: css(d, selector), f"the warning on {skillset}:{transition} at step {index}")
            seen.append((index, skillset, transition, prop, rows[0]["data-constraint"]))
            assert "explicit" in rows[0]["text"] and "command" in rows[0]["text"]
            # The page's check box asks the monitor about the same command.
            browser.execute_script("document.getElementById('check-command').value = arguments[0];"
                                   "document.querySelector('#check-form button').click();", f"{skillset}:{transition}")
            verdict = until(browser, lambda d: css(d, "#check-result [data-decision]"), "the check's answer")
            assert verdict[0]["data-decision"] == "warn" and f"{prop}: explicit (warn)" in css(
                browser, "#check-result")[0]["text"]
            if index == WARNINGS[0][0]:
                screenshot(browser, tmp_path, "dashboard-assisted-warning.png")
                # Spot is powered on: init_power cannot fire, and the answer says so rather than allow it.
                browser.execute_script("document.getElementById('check-result').replaceChildren();"
                                       "document.getElementById('check-command').value = 'spot:init_power.start';"
                                       "document.querySelector('#check-form button').click();")
                idle = until(browser, lambda d: css(d, "#check-result [data-enabled=false]"), "the check's answer")
                assert idle[0]["text"].startswith("spot:init_power.start: NOT FIRABLE (not enabled at the live "
                                                  "marking; if it were: "), idle

    records = play("assisted", router, after)
    assert seen == [(i, s, t, p, "explicit") for i, s, t, p in WARNINGS]
    assert [w.property for r in records for w in r.warnings] == [p for *_, p in WARNINGS]
    assert css(browser, "#violations li.none") and not css(browser, "#violations li[data-property]")


def test_forced_warning_is_shown_with_its_kind_and_witness(browser, dashboard, router, tmp_path) -> None:
    """The mobile manipulator (issue 9's example): driving off while the arm unfolds is forced."""
    browser.get(dashboard(system=REPO / "skillsets" / "mobile_manip.toml"))
    until(browser, lambda d: css(d, "#status[data-connected=true]"), "the live status")
    rows: list[dict[str, str]] = []

    def after(record: StepRecord) -> None:
        if record.index == 3:  # arm:unfold.start
            selector = "#unsafe .group[data-skillset=base] tr[data-transition='navigate.start'][data-constraint=forced]"
            rows.extend(until(browser, lambda d: css(d, selector), "navigate.start flagged forced"))
            badge = css(browser, f"{selector} .kind")[0]
            assert (badge["text"], badge["class"]) == ("forced", "kind kind-forced")
            screenshot(browser, tmp_path, "dashboard-forced.png")

    play("mobile_unassisted", router, after)
    assert rows and rows[0]["data-property"] == "stowed_drive"
    assert "arm:unfold.success.unfolded" in rows[0]["text"] and "uncontrollable" not in rows[0]["text"]


# -- reconnection, late joining, bad input ----------------------------------------------------


def test_page_follows_monitor_and_router_restarts_and_its_own_server_restart(browser, dashboard, spawn, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_router(endpoint)
    system, _ = load_system(SYSTEM_FILE)
    session = open_client(endpoint)
    monitor = start_monitor(session, system)
    events = Events(session)
    events.send("spot", "init_power.start")
    port = free_port()
    proc = spawn("services.dashboard", str(SYSTEM_FILE), "--port", str(port), *client_args(endpoint))
    url = f"http://127.0.0.1:{port}/"
    wait_http(url + "api/snapshot")
    try:
        browser.get(url)  # joined late: the monitor's last step is shown at once
        until(browser, lambda d: css(d, "body")[0]["data-seq"] == "1", "step 1")
        until(browser, lambda d: css(d, "#services [data-service=monitor][data-alive='1']"), "the monitor alive")

        monitor.close()  # monitor restart: a new epoch starting at step 0
        until(browser, lambda d: css(d, "#services [data-service=monitor][data-alive='0']"), "the monitor gone")
        assert "hidden" not in css(browser, "#notice")[0]
        monitor = start_monitor(session, system)
        until(browser, lambda d: css(d, "body")[0]["data-epoch"] == "1", "epoch 1")
        until(browser, lambda d: css(d, "#services [data-service=monitor][data-alive='1']"), "the monitor back")

        router.close()  # router restart: both Zenoh clients reconnect by themselves
        until(browser, lambda d: css(d, "#services [data-service=monitor][data-alive='0']"), "the link lost", 30)
        router = open_router(endpoint)
        until(browser, lambda d: css(d, "#services [data-service=monitor][data-alive='1']"), "the link back", 30)
        events.synced()  # the monitor resynced after the outage (docs/semantics.md §7): the next event is live
        events.send("spot", "init_power.success.powered_on")
        until(browser, lambda d: "init_power.success.powered_on" in css(d, "#step")[0]["text"], "the next event", 20)

        proc.terminate()  # the dashboard's own restart: EventSource reconnects to a fresh snapshot
        proc.wait(10)
        until(browser, lambda d: css(d, "#status[data-connected=false]"), "the lost connection")
        spawn("services.dashboard", str(SYSTEM_FILE), "--port", str(port), *client_args(endpoint))
        until(browser, lambda d: css(d, "#status[data-connected=true]"), "the connection back", 30)
        until(browser, lambda d: "init_power.success.powered_on" in css(d, "#step")[0]["text"], "the last step again")
        screenshot(browser, tmp_path, "dashboard-restarts.png")
    finally:
        monitor.close()
        session.close()
        router.close()


def test_a_lost_bridge_is_shown_plainly_until_it_is_back(browser, dashboard, router, tmp_path) -> None:
    """docs/semantics.md §7: with the bridge gone, the page says in red which skillsets are lost, since when and
    why; while they resync, in yellow; once live again, nothing."""
    session = open_client(router)
    system, _ = load_system(SYSTEM_FILE)
    monitor = start_monitor(session, system)
    try:
        browser.get(dashboard())
        events = Events(session)
        events.send("spot", "init_power.start")
        until(browser, lambda d: css(d, "body")[0]["data-seq"] == "1", "step 1")
        assert "hidden" in css(browser, "#stale")[0]
        assert {c["data-skillset"]: c["data-sync"] for c in css(browser, "#skillsets .card")} == {
            "spot": "live", "manipulator": "live"}
        events.close()  # the bridge stops: its token goes at once
        banner = until(browser, lambda d: [b for b in css(d, "#stale") if "hidden" not in b], "the banner")[0]
        assert banner["data-state"] == "lost" and banner["text"].startswith("STATE NOT LIVE: ")
        assert re.search(r"spot LOST since \d\d:\d\d:\d\d: the liveliness token of 'test' is gone", banner["text"])
        color = browser.execute_script("return getComputedStyle(document.getElementById('stale')).backgroundColor")
        assert color == "rgb(198, 40, 40)"  # --bad
        cards = {c["data-skillset"]: c for c in css(browser, "#skillsets .card")}
        assert cards["spot"]["data-sync"] == "lost" and "LOST since" in cards["spot"]["text"]
        screenshot(browser, tmp_path, "dashboard-lost.png")
        # The page's check box: never a plain allow on a lost state.
        browser.execute_script("document.getElementById('check-command').value = 'spot:init_power.interrupt';"
                               "document.querySelector('#check-form button').click();")
        verdict = until(browser, lambda d: css(d, "#check-result [data-decision]"), "the check's answer")
        assert verdict[0]["data-decision"] == "warn" and "state_unknown (warn)" in css(browser, "#check-result")[0]["text"]
        Events(session)  # the bridge is back: resynced, then live
        until(browser, lambda d: "hidden" in css(d, "#stale")[0], "the banner gone")
        assert {c["data-sync"] for c in css(browser, "#skillsets .card")} == {"live"}
    finally:
        monitor.close()
        session.close()


def test_port_in_use_and_unknown_system_are_one_line_errors(router, tmp_path) -> None:
    import subprocess
    import sys

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        out = subprocess.run([sys.executable, "-m", "services.dashboard", str(SYSTEM_FILE), "--port", str(port),
                              *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=30)
    assert out.returncode == 1
    assert out.stderr.strip() == (f"python -m services.dashboard: error: cannot listen on 127.0.0.1:{port}: "
                                  f"the port is in use (choose another port)")
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "services.dashboard", "no_such_system", "--port", str(port),
                             "--wait", "0.5", *client_args(router)], cwd=REPO, stderr=subprocess.PIPE, text=True)
    try:
        lines = [proc.stderr.readline().strip() for _ in range(2)]
    finally:
        proc.terminate()
        proc.wait(10)
    assert lines[0] == f"skinet dashboard: system no_such_system on http://127.0.0.1:{port}/"
    assert lines[1].endswith("no monitor of system 'no_such_system' is alive (no monitor is reachable at all); "
                             "waiting for one")


def test_board_joins_steps_in_any_order_and_counts_violations_once() -> None:
    board = Board("s")

    def state(seq: int, event: str = "", stamp: float | None = None) -> LiveState:
        return LiveState(system="s", seq=seq, stamp=100.0 + seq if stamp is None else stamp, skillsets={}, event=event)

    def verdicts(seq: int, ok: bool, stamp: float | None = None) -> Verdicts:
        return Verdicts(system="s", seq=seq, stamp=100.0 + seq if stamp is None else stamp,
                        properties=[PropertyVerdict(name="p", holds=ok)])

    board.feed(state(0), 0)
    board.feed(verdicts(0, True), 0)
    assert board.feed(verdicts(1, False), 0) == []  # before its state: it waits
    kinds = [u["kind"] for u in board.feed(state(1, "a:x#0"), 0)]
    assert kinds == ["state", "point", "verdicts", "violation", "point"]
    board.feed(UnsafeReport(system="s", seq=1, stamp=101.5, unsafe=[], literal_count=7, prediction_stale=False), 0)
    assert board.feed(state(1, "a:x#0"), 0, initial=True) == []  # a late copy of what is shown
    assert board.feed(verdicts(1, False), 0, initial=True) == []
    board.feed(state(2, "a:y#1"), 0)
    board.feed(verdicts(2, False), 0)  # still violated: no new onset
    # The same step published again (its sync state changed, docs/semantics.md §7): shown in place, no restart.
    assert [u["kind"] for u in board.feed(state(2, "a:y#1", stamp=150.0), 0)] == ["state"]
    assert board.state.stamp == 150.0 and board.epoch == 0
    restart = board.feed(state(0, stamp=200.0), 0)  # a restarted monitor
    assert restart[0] == {"kind": "restart", "epoch": 1, "t": 0}
    board.feed(verdicts(0, False, stamp=200.0), 0)  # violated from the start of the new epoch
    board.feed(state(1, "a:z#0", stamp=201.0), 0)
    # Another restart whose publications were missed (the view's link was down): the answer to the query that
    # the new monitor's token triggers has an earlier step but a later stamp.  Not a late copy: a new epoch.
    assert board.feed(state(0, stamp=250.0), 0, initial=True)[0] == {"kind": "restart", "epoch": 2, "t": 0}
    assert board.feed(state(0, stamp=240.0), 0, initial=True) == []  # a late copy of an older step of that run
    assert (board.epoch, board.state.stamp) == (2, 250.0)
    snap = json.loads(json.dumps(board.snapshot()))
    assert [(v["property"], v["seq"], v["epoch"], v["event"]) for v in snap["violations"]] == [
        ("p", 1, 0, "a:x#0"), ("p", 0, 1, "")]
    assert [(p["epoch"], p["seq"], p["holds"], p["literal"]) for p in snap["points"]] == [
        (0, 0, {"p": True}, None), (0, 1, {"p": False}, 7), (0, 2, {"p": False}, None), (1, 0, {"p": False}, None),
        (1, 1, {"p": False}, None), (2, 0, {}, None)]


def test_a_late_view_says_a_violation_was_there_when_it_joined_not_that_it_began_then() -> None:
    """A property already violated at the first step a view sees (past step 0) is listed as such, without an
    event: its onset happened before the view joined.  Later onsets carry their step and event."""
    def state(seq: int, event: str) -> LiveState:
        return LiveState(system="s", seq=seq, stamp=100.0 + seq, skillsets={}, event=event)

    def verdicts(seq: int, ok: bool) -> Verdicts:
        return Verdicts(system="s", seq=seq, stamp=100.0 + seq, properties=[PropertyVerdict(name="p", holds=ok)])

    for initial in (True, False):  # the start-up query's answer, or a live step first
        board = Board("s")
        board.feed(state(5, "a:x#4"), 0, initial=initial)
        [update] = [u for u in board.feed(verdicts(5, False), 0, initial=initial) if u["kind"] == "violation"]
        assert update["violation"] == {"n": 0, "property": "p", "seq": 5, "epoch": 0, "event": "", "t": 105.0,
                                       "joined": True}
        for seq, ok in ((6, False), (7, True), (8, False)):
            board.feed(state(seq, f"a:y#{seq - 1}"), 0)
            board.feed(verdicts(seq, ok), 0)
        assert [(v["seq"], v["event"], v["joined"]) for v in board.violations] == [(5, "", True), (8, "a:y#7", False)]


def test_board_keeps_the_pilots_last_status() -> None:
    """A late copy of the pilot's status (its answer to the start-up query) never hides a newer one; a
    restarted pilot (another instance) counts from 0 again."""
    board = Board("s")

    def status(seq: int, state: str, pilot: str = "p1") -> PilotStatus:
        return PilotStatus(system="s", pilot=pilot, seq=seq, stamp=float(seq), state=state)

    assert board.feed(status(2, "driving"), 0) == [{"kind": "pilot", "message": status(2, "driving").model_dump(
        mode="json")}]
    assert board.feed(status(1, "planning"), 0, initial=True) == []
    assert board.feed(status(2, "driving"), 0) == []
    assert [u["message"]["state"] for u in board.feed(status(3, "reached"), 0)] == ["reached"]
    assert [u["message"]["state"] for u in board.feed(status(0, "idle", "p2"), 0)] == ["idle"]
    assert board.snapshot()["pilot"]["pilot"] == "p2"


def test_skinet_run_serves_the_dashboard_beside_its_monitor(tmp_path) -> None:
    import subprocess
    import sys

    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "run", str(SYSTEM_FILE), "--duration", "30",
                             "--no-multicast-scouting", "--dashboard", str(port)], cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr.readline().strip() == f"dashboard on http://127.0.0.1:{port}/"
        deadline = time.monotonic() + 15
        while True:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/snapshot", timeout=2) as r:
                snap = json.load(r)
            if snap["state_space"] is not None or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        assert snap["state"]["seq"] == 0 and snap["state_space"]["markings"] > 0  # the embedded predictor answered
        assert len(snap["alive"]["monitor"]) == 1 and len(snap["alive"]["predictor"]) == 1
        # No bridge connected: the monitor cannot vouch for the marking, so the check warns (docs/semantics.md §7).
        assert {n: s["state"] for n, s in snap["state"]["sync"].items()} == {"spot": "syncing", "manipulator": "syncing"}
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/check?command=spot:init_power.start",
                                    timeout=2) as r:
            reply = json.load(r)
        assert (reply["decision"], [x["constraint"] for x in reply["reasons"]]) == ("warn", ["state_unknown"])
        busy = subprocess.run([sys.executable, "-m", "skinet_cli.main", "run", str(SYSTEM_FILE), "--once",
                               "--no-multicast-scouting", "--dashboard", str(port)], cwd=REPO, capture_output=True,
                              text=True, timeout=60)
        assert (busy.returncode, busy.stderr.strip()) == (
            1, f"skinet: error: cannot listen on 127.0.0.1:{port}: the port is in use (choose another port)")
    finally:
        proc.terminate()
        assert proc.wait(15) == 0


def test_no_violation_reads_none_not_a_numbered_none(browser, dashboard) -> None:
    """The empty violations list showed "1. none" (a numbered list item); it reads "none"."""
    browser.get(dashboard())
    # With no pilot ever seen, its panel is one line (docs/semantics.md §8's goal box has nobody to send goals to).
    until(browser, lambda d: css(d, "#status[data-connected=true]"), "the live status")
    assert browser.execute_script("return document.getElementById('pilot-panel').innerText").strip() == (
        "Pilot (no pilot alive: skinet run starts one, or python -m services.pilot)")
    until(browser, lambda d: css(d, "#violations li.none"), "the empty violations list")
    marker = browser.execute_script(
        "return getComputedStyle(document.querySelector('#violations li.none')).listStyleType")
    assert marker == "none"
    assert browser.execute_script("return document.getElementById('violations').innerText").strip() == "none"


# -- divergences and manager restarts stay listed; the timeline zooms and pans (issue 27 item 4) ------------

NOT_ENABLED = "'init_power.success.powered_on' is not enabled in the live marking"
RESTART_INFO = "manager restarted (the manager (or its gateway) came back); same state as before"


@pytest.fixture
def monitored(router: str) -> Iterator[tuple[object, object]]:
    """A monitor of the paper's system on a client of ``router``: (its session, the monitor)."""
    session = open_client(router)
    monitor = start_monitor(session, load_system(SYSTEM_FILE)[0])
    try:
        yield session, monitor
    finally:
        monitor.close()
        session.close()


def divergence_items(driver) -> list[tuple[str, str, str]]:
    return [(d["data-kind"], d["data-seq"], d["text"]) for d in css(driver, "#divergences li[data-kind]")]


def test_divergences_stay_listed_for_the_run_and_a_late_page_gets_them(browser, dashboard, monitored, tmp_path):
    session, _ = monitored
    browser.get(dashboard())
    until(browser, lambda d: css(d, "#status[data-connected=true]"), "the live status")
    assert css(browser, "#divergences li.none") and css(browser, "#divergence-count")[0]["text"] == "(0)"
    events = Events(session)
    events.send("spot", "init_power.success.powered_on")  # step 1: init_power never started
    items = until(browser, lambda d: divergence_items(d), "the divergence listed")
    assert re.fullmatch(r"model divergence at monitor step 1 \(\d\d:\d\d:\d\d\): "
                        rf"spot:init_power.success.powered_on#1 \u2014 {NOT_ENABLED}", items[0][2]), items
    assert "hidden" not in css(browser, "#divergence")[0]  # the step's own banner, as before
    for skillset, transition in TEN:  # steps 2 to 11
        events.send(skillset, transition)
    until(browser, lambda d: css(d, "body")[0]["data-seq"] == "11", "ten more steps")
    assert "hidden" in css(browser, "#divergence")[0]  # the banner lasted its step ...
    assert divergence_items(browser) == items  # ... the list did not
    marks = css(browser, "#timeline .divergence-mark")
    assert [(m["data-n"], m["data-kind"], m["data-seq"]) for m in marks] == [("0", "divergence", "1")]
    assert NOT_ENABLED in marks[0]["text"]  # its tooltip
    # A manager restart (the bridge says so in its event) in the same state: no step, listed at the step
    # shown, with the bridge's words.
    events.send("spot", None, restart=True, info=RESTART_INFO,
                status={"resources": {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Idle"},
                        "running": []})
    until(browser, lambda d: len(divergence_items(d)) == 2, "the restart listed")
    kind, seq, text = divergence_items(browser)[1]
    assert (kind, seq) == ("restart", "11") and text.endswith(f"spot:status#12 \u2014 {RESTART_INFO}"), text
    screenshot(browser, tmp_path, "dashboard-divergences.png")

    # A page of a dashboard started now (it joined late) gets the list so far from the monitor.
    browser.get(dashboard())
    until(browser, lambda d: len(divergence_items(d)) == 2, "the list on a late page")
    assert divergence_items(browser) == items + [(kind, seq, text)]
    assert css(browser, "#divergence-count")[0]["text"] == "(2)"
    # Its timeline starts at the step it joined at (11): the restart is marked, the earlier divergence only
    # listed.
    assert [m["data-kind"] for m in css(browser, "#timeline .divergence-mark")] == ["restart"]


def window(driver) -> tuple[float, float, str]:
    box = css(driver, "#timeline")[0]
    return float(box["data-t0"]), float(box["data-t1"]), box["data-zoomed"]


def test_the_timeline_zooms_and_pans_and_never_cuts_its_labels(browser, dashboard, monitored, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin

    session, _ = monitored
    browser.get(dashboard())
    until(browser, lambda d: css(d, "body")[0]["data-seq"] == "0", "the start")
    events = Events(session)
    for skillset, transition in TEN:  # a run of about 8 s
        events.send(skillset, transition)
        time.sleep(0.8)
    until(browser, lambda d: css(d, "body")[0]["data-seq"] == "10", "the run")
    first = float(browser.execute_script("return view.points[0].t"))
    t0, t1, zoomed = window(browser)
    assert (t0, zoomed) == (round(first, 3), "false") and t1 - t0 > 8
    # Lane names are whole (none starts left of the picture); a state's name stays inside its shape.
    overflow = browser.execute_script("""
        const out = [];
        for (const t of document.querySelectorAll('#timeline .lane-label'))
          if (t.getBBox().x < 0) out.push('lane ' + t.textContent);
        for (const t of document.querySelectorAll('#timeline .state-label')) {
          const r = t.previousElementSibling.getBBox(), b = t.getBBox();
          if (b.x + b.width > r.x + r.width + 0.5) out.push('state ' + t.textContent);
        }
        return out;""")
    assert overflow == []
    assert css(browser, "#timeline .lane-label")  # drawn

    browser.find_element("id", "zoom-in").click()  # half the span, at the live edge
    until(browser, lambda d: window(d)[2] == "true", "the zoomed window")
    z0, z1, _ = window(browser)
    assert abs((z1 - z0) - (t1 - t0) / 2) < 1.0 and z1 >= t1 - 0.01

    svg = browser.find_element("id", "timeline")
    left = float(browser.execute_script("return frame.left"))
    plot_w = float(browser.execute_script("return frame.plotW"))
    width = float(svg.get_attribute("width"))
    at = left + plot_w / 2  # the wheel at the middle of the plot: the time there stays put
    middle = z0 + (z1 - z0) / 2
    ActionChains(browser).scroll_from_origin(ScrollOrigin.from_element(svg, int(at - width / 2), 0), 0, -100) \
        .perform()
    until(browser, lambda d: window(d)[1] - window(d)[0] < (z1 - z0) * 0.9, "the wheel's zoom")
    w0, w1, _ = window(browser)
    assert abs((w1 - w0) - 0.8 * (z1 - z0)) < 0.5 and abs((w0 + w1) / 2 - middle) < 0.5

    # A drag of 200 px to the right shows earlier times, the same span.
    ActionChains(browser).move_to_element_with_offset(svg, int(at - width / 2), 0).click_and_hold() \
        .move_by_offset(200, 0).release().perform()
    until(browser, lambda d: window(d)[0] < w0 - 0.1, "the pan")
    p0, p1, _ = window(browser)
    shift = 200 / plot_w * (w1 - w0)
    assert abs((p1 - p0) - (w1 - w0)) < 0.01 and abs((w0 - p0) - shift) < 0.3 * shift
    screenshot(browser, tmp_path, "dashboard-zoomed.png")

    browser.find_element("id", "zoom-all").click()  # the whole run again, following it
    until(browser, lambda d: window(d)[2] == "false", "the whole run")
    assert window(browser)[0] == round(first, 3)


# -- the one-command live demo (issue 27 item 5) -------------------------------------------------------------


def test_live_demo_plays_the_mission_for_the_dashboard_and_watch(browser, tmp_path) -> None:
    """``skinet demo --live --dashboard PORT``: the paper's unassisted run through the whole chain at ten times
    real time; the page it serves shows the three violations appear, and the printed watch line reaches it."""
    import subprocess
    import sys

    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "demo", "--live", "--dashboard", str(port),
                             "--speed", "10", "--linger", "60"], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        head = [proc.stderr.readline().rstrip("\n") for _ in range(5)]
        assert head[0] == f"dashboard on http://127.0.0.1:{port}/", head
        endpoint = re.fullmatch(r"skinet demo: system spot_arm, listening on (tcp/127\.0\.0\.1:\d+); connect with:",
                                head[1]).group(1)
        assert head[2:] == [f"  skinet watch spot_arm -e {endpoint}", f"  skinet dashboard spot_arm -e {endpoint}",
                            f"  skinet check spot_arm spot:init_power.start -e {endpoint}"]
        browser.get(f"http://127.0.0.1:{port}/")
        until(browser, lambda d: css(d, "#violations li[data-property]"), "the first violation", 60)
        first = css(browser, "#violations li[data-property]")[0]
        assert (first["data-property"], first["data-event"].split("#")[0]) == ("action_guard", "spot:teleop.start")
        until(browser, lambda d: len(css(d, "#violations li[data-property]")) == 3, "the three violations", 60)
        assert [v["data-property"] for v in css(browser, "#violations li[data-property]")] == [
            p for p, _, _ in VIOLATIONS]
        watch = subprocess.run([sys.executable, "-m", "skinet_cli.main", *head[2].split()[1:], "--once"], cwd=REPO,
                               capture_output=True, text=True, timeout=60)
        assert watch.returncode == 0 and watch.stdout.startswith("SkiNet Live  system spot_arm  step "), \
            watch.stdout + watch.stderr
        lines = watch.stdout.splitlines()  # the onsets are listed for views that join later (issue 30)
        assert "divergences and manager restarts (3)" in lines, watch.stdout
        at = lines.index("divergences and manager restarts (3)")
        assert [line.split(" (")[0] for line in lines[at + 1:]] == [
            "  violation at step 26", "  violation at step 33", "  violation at step 38"], watch.stdout
        assert proc.stderr.readline().startswith("skinet demo: the run is over; the chain keeps running for the "
                                                  "views for 60 s")
    finally:
        proc.terminate()
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:  # once in three full runs of one session (0.3 s is usual): where it hangs
            proc.send_signal(signal.SIGUSR1)
            time.sleep(2)
            proc.kill()
            out, err = proc.communicate()
            pytest.fail(f"skinet demo did not stop within 30 s of SIGTERM; its threads then:\n{err}")
    assert proc.returncode == 0, err
    lines = out.splitlines()
    assert lines[0] == f"== unassisted run ({MISSIONS / 'unassisted.toml'}), live at speed 10: 62 steps, system spot_arm"
    assert "   violations: 3; action_guard at step 26; safety_guard at step 33; action_guard at step 38" in lines
    assert sum(line.startswith("  step ") for line in lines) == 62  # every step, as it was played


def test_the_screenshot_target_photographs_the_live_dashboard(browser, tmp_path) -> None:
    """``make screenshot`` (tests/screenshot.py) writes docs/dashboard.png: here into a temporary folder
    (``browser``: skipped where Chromium is missing, as the script would fail)."""
    import subprocess
    import sys

    from PIL import Image

    out = tmp_path / "dashboard.png"
    done = subprocess.run([sys.executable, "tests/screenshot.py", "-o", str(out), "--speed", "4"], cwd=REPO,
                          capture_output=True, text=True, timeout=180)
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    assert done.stdout == (f"{out}: 1400x{Image.open(out).height} PNG of the live dashboard at step 37, 2 violations, "
                           "violated now: none\n")
    picture = Image.open(out).convert("RGB")
    assert picture.width == 1400 and 1000 < picture.height < 2400
    assert picture.getpixel((5, 5)) == (0x1D, 0x2B, 0x3A)  # the page's header
    colours = {colour for _, colour in picture.getcolors(1 << 24)}
    assert (0xD6, 0x27, 0x28) in colours  # the violated-bar of the timeline (two violations so far)
    assert (0xFB, 0xD3, 0xD0) in colours  # the badge of an explicit constraint: the warning on arm_ready.start


# -- the goal box: goals to the real pilot, its status and plan (docs/semantics.md §8, issue 24 item 4) --------------------

PLAN_STAND_READY = ["1. spot:init_power.start", "2. wait for spot:init_power.success.powered_on",
                    "3. spot:stand_up.start", "4. wait for spot:stand_up.success.standing",
                    "5. manipulator:arm_ready.start", "6. wait for manipulator:arm_ready.success.ready"]
# Every step the page highlights, in order, as a MutationObserver of the plan sees it (repeats dropped).
RECORD_HIGHLIGHTS = """
window.highlights = [];
new MutationObserver(() => {
  const n = document.querySelector('#plan li.step.next > .label');
  const t = n ? n.textContent : null;
  if (t && window.highlights[window.highlights.length - 1] !== t) window.highlights.push(t);
}).observe(document.getElementById('plan'), {childList: true, subtree: true});
"""


def type_goal(driver, text: str) -> None:
    from selenium.webdriver.common.by import By

    box = driver.find_element(By.ID, "goal-text")
    box.clear()
    box.send_keys(text)
    driver.find_element(By.ID, "goal-start").click()


def click(driver, selector: str) -> None:
    from selenium.webdriver.common.by import By

    driver.find_element(By.CSS_SELECTOR, selector).click()


def pilot_state(driver) -> str:
    shown = css(driver, "#pilot-status .pilot-state")
    return shown[0]["data-state"] if shown else ""


def test_the_goal_box_drives_a_goal_with_the_next_step_highlighted(browser, dashboard, client_factory, spot_arm,
                                                                   tmp_path) -> None:
    from selenium.webdriver.common.by import By

    from services.simulator.world import World
    from tests.services.pilot_robot import Robot

    robot = Robot(client_factory, *spot_arm)
    held = [("spot", "init_power"), ("spot", "stand_up"), ("manipulator", "arm_ready")]
    impl = World(robot.sim, duration=0.2, holding=held)  # each ends once the page showed its wait (below)
    try:
        browser.get(dashboard())
        until(browser, lambda d: css(d, "#services [data-service=pilot][data-alive='1']"), "the pilot alive")
        until(browser, lambda d: pilot_state(d) == "idle", "the idle pilot")

        # A typo is shown in place: the message, the line with a caret under the column, the box outlined.
        type_goal(browser, "reach spot:Standin and manipulator:RD")
        error = until(browser, lambda d: css(d, "#goal-error[data-line]:not([hidden])"), "the parse error")[0]
        assert (error["data-field"], error["data-line"], error["data-column"]) == ("goals", "1", "7")
        assert css(browser, "#goal-error .message")[0]["text"] == (
            "goal line 1, column 7: unknown name 'spot:Standin' (candidates: spot:Standing, spot:posture.Standing)")
        assert css(browser, "#goal-error .excerpt")[0]["text"] == "reach spot:Standin and manipulator:RD\n      ^"
        assert "invalid" in css(browser, "#goal-text")[0]["class"]
        screenshot(browser, tmp_path, "dashboard-goal-error.png")
        # The pilot's own refusal (no plan) is shown too, with its reason.
        type_goal(browser, "reach spot:Busy and manipulator:Busy")
        until(browser, lambda d: css(d, "#goal-error[data-rejected=true]:not([hidden])"), "the pilot's refusal")
        assert "has no plan from the live state: none: the goal is unsafe" in css(browser, "#goal-error")[0]["text"]

        # A good goal in drive mode: the plan, its next step highlighted as the pilot moves on, then reached.
        click(browser, "input[name=goal-mode][value=drive]")
        browser.execute_script(RECORD_HIGHLIGHTS)
        type_goal(browser, "reach spot:Standing and manipulator:RD")
        until(browser, lambda d: css(d, "#goal-error[hidden]"), "the error gone")
        until(browser, lambda d: pilot_state(d) == "waiting for outcome", "the first command on its way")
        screenshot(browser, tmp_path, "dashboard-goal-driving.png")
        # Each skill runs until the page's own record shows the wait for its outcome highlighted: what is asserted
        # is that the page follows the pilot, not how fast a loaded machine renders a one-second wait.
        for (skillset, skill), wait in zip(held, PLAN_STAND_READY[1::2]):
            until(browser, lambda d: wait in d.execute_script("return window.highlights"), f"'{wait}' highlighted", 60)
            if skill == "stand_up":
                screenshot(browser, tmp_path, "goalbox.png", "pilot-panel")  # docs/goalbox.png
            impl.release(skillset, skill)
        until(browser, lambda d: pilot_state(d) == "reached", "the goal reached", 60)
        labels = [s["text"] for s in css(browser, "#plan > li.step > .label")]
        assert labels == PLAN_STAND_READY
        seen = browser.execute_script("return window.highlights")
        assert seen == sorted(seen, key=PLAN_STAND_READY.index), seen  # it only moved on
        assert set(PLAN_STAND_READY[1::2]) <= set(seen), seen  # every wait for an outcome
        assert not css(browser, "#plan li.step.next")  # reached: nothing left to do
        assert robot.actuator.sent == ["spot:init_power.start", "spot:stand_up.start", "manipulator:arm_ready.start"]
        facts = {f["data-fact"]: f["text"] for f in css(browser, "#pilot-status [data-fact]")}
        assert facts["commands"] == "3 commands sent" and facts["mode"] == "drive mode" and "denied" not in facts

        # Guide mode with skill inputs, pause, resume, then switched to drive and cancelled while its skill runs.
        impl.holding.add(("manipulator", "arm_RD_to_HP"))
        click(browser, "input[name=goal-mode][value=guide]")
        browser.find_element(By.ID, "goal-inputs").send_keys("go_to_waypoint.target = {x = 12.0, y = 3.5, z = 0.0}")
        type_goal(browser, "run spot:go_to_waypoint")
        until(browser, lambda d: pilot_state(d) == "guiding", "guiding")
        next_step = until(browser, lambda d: css(d, "#plan li.step.next"), "the highlighted step")[0]
        assert (next_step["data-number"], next_step["data-action"]) == ("1", "arm_RD_to_HP.start")
        assert "3. spot:go_to_waypoint.start with {target = {x = 12, y = 3.5, z = 0}}" in [
            s["text"] for s in css(browser, "#plan li.step > .label")]
        click(browser, "#goal-pause")
        until(browser, lambda d: pilot_state(d) == "paused", "paused")
        assert css(browser, "#goal-pause")[0].get("disabled") is not None
        assert css(browser, "#goal-resume")[0].get("disabled") is None
        click(browser, "#goal-resume")
        until(browser, lambda d: pilot_state(d) == "guiding", "guiding again")
        assert robot.actuator.sent[-1] == "manipulator:arm_ready.start"  # guide mode sent nothing
        click(browser, "input[name=goal-mode][value=drive]")
        until(browser, lambda d: robot.actuator.sent[-1] == "manipulator:arm_RD_to_HP.start", "the command sent in drive")
        click(browser, "#goal-cancel")
        until(browser, lambda d: pilot_state(d) == "cancelled", "cancelled")
        assert css(browser, "#goal-cancel")[0].get("disabled") is not None
        screenshot(browser, tmp_path, "dashboard-goal-cancelled.png")

        # The pilot gone: the box stays (its last status too), and a goal gets the reason nobody took it.
        robot.pilot.close()
        until(browser, lambda d: css(d, "#pilot-panel[data-pilot=gone]"), "the pilot gone")
        type_goal(browser, "reach spot:Standing")
        until(browser, lambda d: css(d, "#goal-error:not([hidden])"), "the error")
        assert css(browser, "#goal-error .message")[0]["text"] == (
            "no pilot answers on skinet/spot_arm/pilot/goal/local: is `skinet run` or the pilot service running?")
    finally:
        impl.close()
        robot.close()


def test_the_goal_box_asks_how_a_skill_that_ended_unseen_ended(browser, dashboard, client_factory, spot_arm) -> None:
    """teleop ends while the monitor restarts: the box shows the skill and the gap with three answers, and
    'It succeeded' lets the pilot reach the goal without starting teleop again."""
    from services.simulator.world import World
    from tests.services.pilot_robot import Robot
    from tests.services.test_pilot_gaps import restart_monitor_while

    robot = Robot(client_factory, *spot_arm)
    impl = World(robot.sim, holding=[("spot", "teleop")])
    try:
        browser.get(dashboard())
        until(browser, lambda d: pilot_state(d) == "idle", "the idle pilot")
        assert css(browser, "#goal-unknown[hidden]")
        click(browser, "input[name=goal-mode][value=drive]")
        type_goal(browser, "run spot:teleop")
        robot.statuses.first(lambda s: s.reason == "the outcome of spot:teleop", what="teleop running")
        restart_monitor_while(robot, impl, "teleop")
        until(browser, lambda d: css(d, "#goal-unknown:not([hidden])"), "the question", 60)
        assert css(browser, "#goal-unknown-text")[0]["text"] == (
            "How did spot:teleop end (while the monitor was restarted)?")
        click(browser, ".goal-answer[data-answer=success]")
        until(browser, lambda d: pilot_state(d) == "reached", "the goal reached", 60)
        assert css(browser, "#goal-unknown[hidden]")
        assert robot.actuator.sent.count("spot:teleop.start") == 1
    finally:
        impl.close()
        robot.close()
