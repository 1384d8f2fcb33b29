"""``skinet rosbag``: the bridge's inputs recorded through Zenoh as a rosbag2 that ``skinet conform`` and
rosbag2 readers take (docs/robot.md, *Recording a bag without ROS*; issue 32, item 6)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import pytest
import zenoh
from rosbags.highlevel import AnyReader

from services.bridge_ros2.record import BagRecorder, recorded_topics
from services.simulator.bound import BoundSimulator
from services.simulator.service import Simulator
from skinet.system.load import load_bindings, load_system, load_typemap
from skinet.files.read import read_text
from skinet.mission.scenario import parse_scenario
from skinet.ros.keys import KeyStyle
from skinet_cli.main import main

REPO = Path(__file__).resolve().parents[2]
NAV2 = REPO / "examples" / "nav2"
SPOT_ARM = REPO / "skillsets" / "spot_arm.toml"
UNASSISTED = REPO / "skillsets" / "missions" / "unassisted.toml"


def _conform(capsys: pytest.CaptureFixture[str], system: Path, bag: Path) -> tuple[int, str]:
    capsys.readouterr()
    code = main(["conform", str(system), str(bag)])
    return code, capsys.readouterr().out


def _wait_for(recorder: BagRecorder, done: Callable[[], bool], timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f"{recorder.messages} messages recorded: {recorder.counts}"
        time.sleep(0.05)


def _wait_for_match(publisher: zenoh.Publisher, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not publisher.matching_status.matching:
        assert time.monotonic() < deadline, "no subscriber of the recorder reached the router"
        time.sleep(0.05)


def _statuses(recorder: BagRecorder, skillsets: Iterable[str]) -> dict[str, int]:
    return {name: n for name in skillsets for topic, n in recorder.counts.items()
            if topic.endswith(f"/{name}_skillset/status")}


@pytest.mark.parametrize("style", [KeyStyle(), KeyStyle(rmw_zenoh=True)], ids=["zenoh-bridge-ros2dds", "rmw_zenoh"])
def test_a_managed_robot_recorded_conforms(client_factory, style: KeyStyle, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The paper's unassisted run, recorded from the simulated managers: every message the managers published
    is in the bag, ROS readers see the topics with their types, and conform finds the run's steps with no
    divergence."""
    system, _ = load_system(SPOT_ARM)
    typemap = load_typemap(SPOT_ARM)
    topics = recorded_topics(system, typemap, {}, style)
    assert {t.name for t in topics} >= {"/spot/spot_skillset_manager/spot_skillset/status",
                                        "/kinova/manipulator_skillset_manager/manipulator_skillset/status"}
    recorder = BagRecorder(client_factory(), tmp_path / "run", topics)
    _wait_for_match(client_factory().declare_publisher(topics[0].key))  # its subscriptions reach the router
    sim = Simulator(client_factory(), system, typemap, style=style)
    try:
        sim.drive(parse_scenario(read_text(UNASSISTED), "unassisted.toml"), speed=0)
        published = sim.statuses_published()
        _wait_for(recorder, lambda: _statuses(recorder, published) == published)
    finally:
        sim.close()
        recorder.close()
    with AnyReader([tmp_path / "run"]) as reader:
        assert {c.topic: c.msgtype for c in reader.connections}[
            "/spot/spot_skillset_manager/spot_skillset/status"] == "spot_skillset_interfaces/msg/SkillsetStatus"
        assert sum(1 for _ in reader.messages()) == recorder.messages
    code, out = _conform(capsys, SPOT_ARM, tmp_path / "run")
    assert code == 0, out
    first = out.splitlines()[0]
    assert first.startswith(f"{tmp_path / 'run'}: {recorder.messages} messages, ") and \
        first.endswith(", 0 model divergences"), out


def test_a_bound_robot_recorded_conforms(client_factory, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The Nav2 example (no skillset manager): action statuses, the lidar's lifecycle and the battery topic."""
    system, _ = load_system(NAV2 / "nav2.toml")
    bindings, _ = load_bindings(system)
    scenario = parse_scenario(read_text(NAV2 / "missions" / "nav2_run.toml"), "nav2_run.toml")
    topics = recorded_topics(system, {}, bindings)
    recorder = BagRecorder(client_factory(), tmp_path / "nav2", topics, storage="sqlite3")
    _wait_for_match(client_factory().declare_publisher(topics[-1].key))
    robot = BoundSimulator(client_factory(), system, bindings)
    try:
        robot.publish_topics(scenario.topics)
        robot.drive(scenario, speed=0, on_step=lambda _: time.sleep(0.02))
        _wait_for(recorder, lambda: recorder.messages >= 21)
    finally:
        robot.close()
        recorder.close()
    code, out = _conform(capsys, NAV2 / "nav2.toml", tmp_path / "nav2")
    assert code == 0, out
    assert out.splitlines()[0] == f"{tmp_path / 'nav2'}: {recorder.messages} messages, 12 events, 0 model divergences"


def test_the_command_records_until_sigterm_and_conform_reads_its_bag(router: str, client_factory, zenoh_args,
                                                                      tmp_path: Path) -> None:
    system, _ = load_system(SPOT_ARM)
    typemap = load_typemap(SPOT_ARM)
    bag = tmp_path / "cli"
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "rosbag", str(SPOT_ARM), "-o", str(bag),
                             *zenoh_args], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()  # type: ignore[union-attr]
        assert line == f"skinet rosbag: recording 16 topics of spot_arm to {bag} (mcap)\n", line
        status = next(t for t in recorded_topics(system, typemap, {}) if t.name.endswith("/spot_skillset/status"))
        probe = client_factory().declare_publisher(status.key)  # its subscriptions reach the router, then we play
        _wait_for_match(probe)
        sim = Simulator(client_factory(), system, typemap)
        try:
            sim.drive(parse_scenario(read_text(UNASSISTED), "unassisted.toml"), speed=0)
            time.sleep(1.0)
        finally:
            sim.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert err.rstrip().splitlines()[-1].startswith("skinet rosbag: ") and \
        f"messages written to {bag}; replay it with skinet conform {SPOT_ARM} {bag}" in err
    done = subprocess.run([sys.executable, "-m", "skinet_cli.main", "conform", str(SPOT_ARM), str(bag)], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.splitlines()[0].endswith(", 0 model divergences"), done.stdout


def test_bad_output_and_an_empty_bag_are_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "taken").mkdir()
    assert main(["rosbag", str(SPOT_ARM), "-o", str(tmp_path / "taken")]) == 1
    assert capsys.readouterr().err == f"{tmp_path / 'taken'}: error: already exists: a rosbag2 is written to a new folder\n"
    assert main(["rosbag", str(SPOT_ARM), "-o", str(tmp_path / "empty"), "--duration", "0.3", "--mode", "peer",
                 "--no-multicast-scouting"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == (f"skinet: error: nothing recorded in {tmp_path / 'empty'}: no message on the 16 topics (is the "
                       "robot or its gateway connected to this Zenoh network? check -e/--connect and --namespace)")
