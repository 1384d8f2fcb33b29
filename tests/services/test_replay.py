"""``skinet replay``: a real recording published again, followed by real observers (issue 27, item 6).

The recording is made as a user makes one: the mobile manipulator's unassisted
mission played by the simulated managers through bridge, monitor and predictor
on a router, with ``skinet record`` running beside it, once as JSON Lines and
once as MCAP.  Each log is then replayed by the ``skinet replay`` command (a
process) and observed with a Zenoh subscriber, late-joining queries, ``skinet
watch``, ``skinet check``, ``skinet record`` then ``skinet timeline``, and the
web dashboard in headless Chromium.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh

from chains.chain import run_chain
from services.monitor import start_monitor
from chains.replay import RESULTS
from skinet.system.load import load_system, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import parse_scenario
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.log import Entry
from skinet.wire.messages import MESSAGES, LiveState, ModelBundle
from skinet_cli.record import decode_any
from skinet_cli.timeline import load_log
from tests.processes import start_skinet, stop
from tests.services.conftest import REPO, client_args, free_port, open_client, open_router
from tests.services.test_dashboard import browser, css, screenshot, until, wait_http  # noqa: F401 (fixture)

SYSTEM_FILE = REPO / "skillsets" / "mobile_manip.toml"
MISSION = REPO / "skillsets" / "missions" / "mobile_unassisted.toml"
NAME = "mobile_manip"
CHAIN_SPEED = 4.0  # the recorded run takes 28 s / 4 of mission time
LAST_STEP = 14


def stopped(proc: subprocess.Popen, log: Path) -> str:
    """SIGTERM ``proc``, wait for its exit (status 0 expected) and return what it printed."""
    code = stop(proc, timeout=20)
    text = log.read_text(errors="replace")
    assert code == 0, text
    return text


def wait_until(predicate, what: str, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.05)


def wait_token(session: zenoh.Session, key_expr: str, timeout: float = 15.0) -> None:
    wait_until(lambda: any(r.ok is not None for r in session.liveliness().get(key_expr, timeout=0.5)),
               f"a liveliness token on {key_expr}", timeout)


def published(entries: list[Entry]) -> list[tuple[str, object]]:
    """The monitor's publications of a log: (key, message) in order."""
    return [(e.key, e.message) for e in entries if e.type in RESULTS]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A real run recorded by ``skinet record``: {"jsonl": path, "mcap": path}."""
    folder = tmp_path_factory.mktemp("recording")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_router(endpoint)
    session = open_client(endpoint)
    logs = {fmt: folder / f"run.{fmt}" for fmt in ("jsonl", "mcap")}
    recorders = {fmt: start_skinet("record", NAME, "-o", str(path), *client_args(endpoint),
                                   log=folder / f"record-{fmt}.out")
                 for fmt, path in logs.items()}
    try:
        wait_until(lambda: len([r for r in session.liveliness().get(keys.alive(NAME, "recorder", "*"), timeout=0.5)
                                if r.ok is not None]) == 2, "both recorders")
        scenario = parse_scenario(read_text(MISSION), str(MISSION))
        system, _ = load_system(SYSTEM_FILE)
        records = run_chain(system, load_typemap(SYSTEM_FILE), scenario, session=session, speed=CHAIN_SPEED)
        assert [(r.index, r.violations) for r in records if r.violations] == [(5, ["stowed_drive"])]

        def done() -> bool:  # the last step's fresh prediction is in the JSON Lines log (flushed per line)
            lines = logs["jsonl"].read_text().splitlines()
            return any('"UnsafeReport"' in x and f'"seq":{LAST_STEP},' in x and '"prediction_stale":false' in x
                       for x in lines)

        wait_until(done, "the last step in the recording")
        time.sleep(0.5)  # the MCAP recorder received it at the same time
    finally:
        outputs = {fmt: stopped(proc, folder / f"record-{fmt}.out") for fmt, proc in recorders.items()}
        session.close()
        router.close()
    entries = {fmt: load_log(str(path)) for fmt, path in logs.items()}
    assert published(entries["jsonl"]) == published(entries["mcap"]), outputs
    for found in entries.values():
        seqs = [e.message.seq for e in found if isinstance(e.message, LiveState)]
        # Every step, in order; a step is published again when its skillsets' sync states change (docs/semantics.md §7).
        assert seqs == sorted(seqs) and sorted(set(seqs)) == list(range(LAST_STEP + 1)), seqs
        assert sum(isinstance(e.message, ModelBundle) for e in found) == 1
    return logs


@pytest.mark.parametrize("fmt", ["jsonl", "mcap"])
def test_replay_publishes_the_recorded_run_as_its_monitor_did(recording: dict[str, Path], router: str, fmt: str,
                                                              tmp_path: Path) -> None:
    log = recording[fmt]
    original = load_log(str(log))
    expected = published(original)
    session = open_client(router)
    received: list[tuple[float, str, object]] = []
    lock = threading.Lock()

    def on_sample(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        message = decode_any(NAME, key, sample.payload.to_bytes())
        with lock:
            received.append((time.monotonic(), key, message))

    subscriber = session.declare_subscriber(f"skinet/{NAME}/**", on_sample)
    again = tmp_path / "again.jsonl"
    recorder = start_skinet("record", NAME, "-o", str(again), *client_args(router), log=tmp_path / "record.out")
    replay = None
    try:
        wait_token(session, keys.alive(NAME, "recorder", "*"))
        replay = start_skinet("replay", str(log), "--speed", "4", *client_args(router), log=tmp_path / "replay.out")
        wait_until(lambda: len(received) >= len(expected), f"{len(expected)} messages", 60)
        time.sleep(0.3)  # nothing more comes
        with lock:
            got = list(received)
        # Every publication of the monitor, on its key, unchanged and in order; no canonical event.
        assert [(key, message) for _, key, message in got] == expected
        # At the recorded pace divided by 4: never early, and not late by more than scheduling noise.
        t0, r0 = next(e.t for e in original if e.type in RESULTS), got[0][0]
        recorded = [e.t - t0 for e in original if e.type in RESULTS]
        late = [(r - r0) - dt / 4 for (r, _, _), dt in zip(got, recorded)]
        assert min(late) > -0.1 and max(late) < 2.0, (min(late), max(late))
        assert recorded[-1] / 4 > 1.0  # the pacing is visible: more than a second of replay

        # Late joiners: the last publication of each key, as the monitor answers; the model bundle.
        for kind, key in RESULTS.items():
            replies = [r.ok for r in session.get(key(NAME), timeout=2) if r.ok is not None]
            last = [m for k, m in expected if k == key(NAME)][-1:]  # Divergences: its violation onsets
            assert [decode(r.payload.to_bytes(), MESSAGES[kind]) for r in replies] == last, kind
        assert {type(m).__name__ for _, m in expected} == set(RESULTS)
        model = next(e.message for e in original if isinstance(e.message, ModelBundle))
        replies = [r.ok for r in session.get(keys.model(NAME), timeout=2) if r.ok is not None]
        assert [decode(r.payload.to_bytes(), ModelBundle) for r in replies] == [model]
        alive = [str(r.ok.key_expr) for r in session.liveliness().get(keys.alive(NAME, "*", "*"), timeout=1)
                 if r.ok is not None and "/monitor/" in str(r.ok.key_expr)]
        assert len(alive) == 1 and alive[0].split("/")[-1].startswith("replay-")

        # skinet watch joins late and shows the last step; skinet check is told this is no live robot.
        last_state = [m for _, m in expected if isinstance(m, LiveState)][-1]
        watch = subprocess.run([sys.executable, "-m", "skinet_cli.main", "watch", NAME, "--once",
                                *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)
        assert watch.returncode == 0, watch.stderr
        assert watch.stdout.startswith(f"SkiNet Live  system {NAME}  step {LAST_STEP}  last event "
                                       f"{last_state.event}\n")
        assert "  stowed_drive: holds\n" in watch.stdout
        assert "services  monitor: 1, bridge_ros2: 0, predictor: 0, pilot: off\n  REPLAY of a recorded run (skinet replay), not the " \
            "live robot\n" in watch.stdout
        check = subprocess.run([sys.executable, "-m", "skinet_cli.main", "check", NAME, "arm:unfold.start",
                                *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)
        assert (check.returncode, check.stdout) == (1, f"arm:unfold.start: error: this is a replay of {log} "
                                                       "(skinet replay), not the live robot: no command check\n")
    finally:
        subscriber.undeclare()
        session.close()
        out = stopped(replay, tmp_path / "replay.out") if replay is not None else ""
        stopped(recorder, tmp_path / "record.out")
    events = sum(e.type == "CanonicalEvent" for e in original)
    beats = sum(e.type == "Heartbeat" for e in original)  # the bridge's (docs/semantics.md §7): never replayed either
    lines = out.splitlines()
    assert beats > 0 and lines[0] == (f"skinet replay: {log}: system {NAME}, {len(expected)} monitor messages over "
                                      f"{recorded[-1]:.1f} s recorded, at speed 4; not published: {events} "
                                      f"CanonicalEvent, {beats} Heartbeat")
    assert re.fullmatch(rf"skinet replay: {len(expected)} messages published in \d+\.\d s; still answering late "
                        r"joiners \(Ctrl-C stops\)", lines[1]), lines[1]
    # Recorded again, the replay is the same run; skinet timeline draws it.
    entries = load_log(str(again))
    assert published(entries) == expected
    assert [e.message for e in entries if isinstance(e.message, ModelBundle)] == [model]
    picture = tmp_path / "again.png"
    drawn = subprocess.run([sys.executable, "-m", "skinet_cli.main", "timeline", str(again), "-o", str(picture)],
                           cwd=REPO, capture_output=True, text=True, timeout=120)
    assert drawn.returncode == 0, drawn.stderr
    assert picture.stat().st_size > 10_000


def test_a_demo_log_replays_as_a_live_state_with_whole_property_names(browser, tmp_path: Path) -> None:
    """A ``skinet demo --log`` log (issue 32, item 8): no "not vouched for" banner, every skillset live beside the
    monitor, and property names on one line in a narrow window."""
    scenario = REPO / "skillsets" / "missions" / "unassisted.toml"
    made = subprocess.run([sys.executable, "-m", "skinet_cli.main", "demo", "--core", "--log", str(tmp_path / "logs"),
                           str(scenario)], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    log = tmp_path / "violated.jsonl"  # the run up to its first violation: a recovery column beside the names
    log.write_text("".join(line + "\n" for line in (tmp_path / "logs" / "unassisted.jsonl").read_text().splitlines()
                           if json.loads(line)["t"] <= 52.0))
    out = tmp_path / "replay.out"
    proc = start_skinet("replay", str(log), "--speed", "0", "--dashboard", "0", log=out)
    try:
        wait_until(lambda: "dashboard on http" in out.read_text(), "the dashboard's address")
        url = out.read_text().split("dashboard on ")[1].split()[0]
        wait_http(url + "api/snapshot")
        browser.set_window_size(360, 900)
        browser.get(url)
        until(browser, lambda d: css(d, "#properties tr[data-property=action_guard][data-holds=false]"),
              "the violated property")
        assert "hidden" in css(browser, "#stale")[0]
        assert {c["data-skillset"]: c["data-sync"] for c in css(browser, "#skillsets .card")} == {
            "spot": "live", "manipulator": "live"}
        pilot = css(browser, "#services [data-service=pilot]")[0]  # none in a demo's run: off, not a failure
        assert (pilot["class"], pilot["text"]) == ("service off", "pilot: off")
        until(browser, lambda d: css(d, "#goal-inputs")[0]["placeholder"] == "go_to_waypoint.target = ...",
              "the placeholders of the model, which a view may get after the messages")
        placeholders = {e["id"]: e["placeholder"] for e in css(browser, "#goal-text, #goal-inputs, #check-command")}
        assert placeholders == {"goal-text": "reach spot:PowerOn\nrun spot:init_power",
                                "goal-inputs": "go_to_waypoint.target = ...",
                                "check-command": "skillset:transition, e.g. spot:init_power.start"}
        lines = browser.execute_script(
            "const r = document.createRange(); const td = document.querySelector("
            "'#properties tr[data-property=action_guard] td'); r.selectNodeContents(td);"
            "return new Set([...r.getClientRects()].map((x) => Math.round(x.top))).size")
        assert lines == 1
    finally:
        stopped(proc, out)


def test_replay_with_dashboard_shows_the_run_live(recording: dict[str, Path], browser, tmp_path: Path) -> None:
    """``--dashboard`` in one process (a peer session, no router): the page follows the replay step by step."""
    out = tmp_path / "replay.out"
    proc = start_skinet("replay", str(recording["mcap"]), "--dashboard", "0", "--no-multicast-scouting", log=out)
    try:
        wait_until(lambda: "dashboard on http" in out.read_text(), "the dashboard's address")
        url = out.read_text().split("dashboard on ")[1].split()[0]
        wait_http(url + "api/snapshot")
        browser.get(url)
        until(browser, lambda d: css(d, "#status[data-connected=true]"), "the live status")
        seen: list[int] = []

        def step(d) -> bool:  # every step the page shows, while the replay runs at the recorded pace
            seq = int(css(d, "body")[0]["data-seq"])
            if not seen or seen[-1] != seq:
                seen.append(seq)
            return seq == LAST_STEP

        until(browser, step, f"step {LAST_STEP}", 30)
        assert len(seen) > 3 and seen == sorted(seen)  # it followed the run, not only its end
        items = css(browser, "#violations li[data-property]")
        assert [(v["data-property"], v["data-seq"]) for v in items] == [("stowed_drive", "5")]
        monitor = css(browser, "#services [data-service=monitor]")[0]
        assert (monitor["data-alive"], monitor["text"]) == ("1", "monitor: replay")
        assert monitor["title"].startswith("replay-")
        notice = css(browser, "#notice")[0]
        assert "hidden" not in notice and notice["text"] == ("Replay of a recorded run (skinet replay), not the live "
                                                            "robot: times are the recording's.")
        assert css(browser, "#timeline .violation-label")
        # The examples name this system's skillsets, not the paper robot's (issue 32, item 7).
        until(browser, lambda d: css(d, "#goal-text")[0]["placeholder"] == "reach base:Moving\nrun base:undock",
              "the placeholders of the model, which a view may get after the messages")
        placeholders = {e["id"]: e["placeholder"] for e in css(browser, "#goal-text, #goal-inputs, #check-command")}
        assert placeholders == {"goal-text": "reach base:Moving\nrun base:undock",
                                "goal-inputs": "no skill of this system takes inputs",
                                "check-command": "skillset:transition, e.g. base:undock.start"}
        browser.execute_script("document.getElementById('check-command').value = 'arm:unfold.start';"
                               "document.querySelector('#check-form button').click();")
        error = until(browser, lambda d: css(d, "#check-result .error"), "the check's answer")
        assert "not the live robot: no command check" in error[0]["text"]
        screenshot(browser, tmp_path, "dashboard-replay.png")
    finally:
        stopped(proc, out)


def test_replay_refuses_to_mix_with_a_live_monitor(recording: dict[str, Path], router: str, tmp_path: Path) -> None:
    session = open_client(router)
    system, _ = load_system(SYSTEM_FILE)
    monitor = start_monitor(session, system)
    try:
        r = subprocess.run([sys.executable, "-m", "skinet_cli.main", "replay", str(recording["jsonl"]),
                            *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)
    finally:
        monitor.close()
        session.close()
    assert (r.returncode, r.stdout, r.stderr) == (1, "", f"skinet: error: a monitor of system '{NAME}' is alive on "
                                                         "this Zenoh network: a replay would mix its messages with "
                                                         "the live ones (stop that monitor, or replay on another "
                                                         "network)\n")


def test_bridge_points_at_skinet_replay_for_a_monitor_log(recording: dict[str, Path]) -> None:
    """``bridge_ros2 --replay`` takes rosbag2 files of the managers; it used to say ``Profile is not ros2``."""
    for fmt, kind in (("mcap", "MCAP"), ("jsonl", "JSON Lines")):
        log = recording[fmt]
        r = subprocess.run([sys.executable, "-m", "services.bridge_ros2", str(SYSTEM_FILE), "--replay", str(log),
                            "--no-multicast-scouting"], cwd=REPO, capture_output=True, text=True, timeout=60)
        assert (r.returncode, r.stderr) == (1, f"{log}: error: a SkiNet monitor log ({kind}, skinet record), not a "
                                               f"rosbag2 file of the managers: replay it with 'skinet replay {log}'\n")


def test_readme_lines_a_peer_replay_and_a_watch_connected_to_it(recording: dict[str, Path], tmp_path: Path) -> None:
    """docs/operator.md's ``skinet replay run.mcap --speed 4 --listen ENDPOINT`` then ``skinet watch --connect ENDPOINT``
    (no router); ``--linger`` ends the replay by itself."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    out = tmp_path / "replay.out"
    proc = start_skinet("replay", str(recording["mcap"]), "--speed", "4", "--listen", endpoint, "--linger", "8",
                  "--no-multicast-scouting", log=out)
    try:
        wait_until(lambda: "messages published" in out.read_text(), "the end of the replay", 30)
        watch = subprocess.run([sys.executable, "-m", "skinet_cli.main", "watch", NAME, "--connect", endpoint,
                                "--once", "--no-multicast-scouting"], cwd=REPO, capture_output=True, text=True,
                               timeout=60)
        assert watch.returncode == 0, watch.stderr
        assert watch.stdout.startswith(f"SkiNet Live  system {NAME}  step {LAST_STEP}  last event ")
        assert proc.wait(timeout=30) == 0
    finally:
        text = stopped(proc, out)
    assert text.splitlines()[-1].endswith("; still answering late joiners for 8 s")


def test_an_unreachable_endpoint_stops_the_replay(recording: dict[str, Path]) -> None:
    """Publishing towards an explicit ``--connect`` endpoint nobody answers at is no replay: one error line
    after the wait, exit 1 (issue 27, item 2, as for watch and record)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    r = subprocess.run([sys.executable, "-m", "skinet_cli.main", "replay", str(recording["jsonl"]), "--connect",
                        endpoint, "--no-multicast-scouting"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stdout) == (1, "")
    # A command line given --connect is a client (issue 30): it fails at once, in one line.
    assert r.stderr.splitlines() == [f"skinet: error: cannot open the Zenoh session: nothing answers at {endpoint}"]
