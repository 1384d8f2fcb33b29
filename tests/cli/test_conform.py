"""``skinet conform SYSTEM BAG...``: recorded bags replayed against the model (docs/semantics.md §9 *Conformance*).

Bags are recorded from the simulated Nav2 robot (real CDR, written by rosbags'
Writer in sqlite3 and in mcap): a clean run gives no divergence and exit 0; a run
with a goal the model forbids, a second concurrent goal, a battery value matching
no state and a lifecycle error gives exactly those four, each with its time and the
model's expectation, and exit 3.  A bag recording a bound topic under another type,
and a bad binding, give one line and exit 1.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import pytest
import zenoh
from rosbags.highlevel import AnyReader

from services.bridge_ros2.record import BagRecorder, recorded_topics
from services.common.zenoh_config import session_config
from services.simulator.bound import BoundSimulator
from skinet.errors import SourceError
from skinet.system.load import load_bindings, load_system
from skinet.files.read import read_text
from skinet.mission.scenario import parse_scenario
from skinet.ros.bound import goal_text
from skinet_cli.main import main

REPO = Path(__file__).resolve().parents[2]
NAV2 = REPO / "examples" / "nav2"
SYSTEM = str(NAV2 / "nav2.toml")
NAV = "/navigate_to_pose/_action/status"


@pytest.fixture(scope="module")
def nav2():
    system, _ = load_system(NAV2 / "nav2.toml")
    bindings, _ = load_bindings(system)
    return system, bindings


def record(nav2, run: Callable[[BoundSimulator], None],  # type: ignore[no-untyped-def]
           bags: Mapping[Path, tuple[str, Mapping[str, str]]]) -> None:
    """Play ``run(robot)`` on the simulated robot while ``skinet rosbag``'s recorder writes each bag of ``bags``
    (path -> storage, and the types some topics are recorded under instead of their own: a wrong bag); a bag
    lacks the topics the run never published on (``not recorded``)."""
    system, bindings = nav2
    topics = recorded_topics(system, {}, bindings)
    session = zenoh.open(session_config("peer", multicast_scouting=False))
    recorders = [BagRecorder(session, path, [dataclasses.replace(t, typename=types.get(t.name, t.typename))
                                             for t in topics], storage=storage, heard_only=True)
                 for path, (storage, types) in bags.items()]
    robot = BoundSimulator(session, system, bindings)
    try:
        run(robot)
        time.sleep(0.2)
    finally:
        for recorder in recorders:
            recorder.close()
        robot.close()
        session.close()


def stamps(bag: Path) -> list[float]:
    """The record times of ``bag``'s messages, in seconds."""
    with AnyReader([bag]) as reader:
        return [ns * 1e-9 for _, ns, _ in reader.messages()]


@pytest.fixture(scope="module")
def clean(nav2, tmp_path_factory) -> dict[str, Path]:  # type: ignore[no-untyped-def]
    scenario = parse_scenario(read_text(NAV2 / "missions" / "nav2_run.toml"), "nav2_run.toml")

    def run(robot: BoundSimulator) -> None:
        robot.publish_topics(scenario.topics)
        robot.drive(scenario, speed=0, on_step=lambda _: time.sleep(0.02))

    folder = tmp_path_factory.mktemp("clean")
    bags = {storage: folder / storage for storage in ("sqlite3", "mcap")}
    record(nav2, run, {path: (storage, {}) for storage, path in bags.items()})
    return bags


@pytest.fixture(scope="module")
def drifting(nav2, tmp_path_factory):  # type: ignore[no-untyped-def]
    """The drifting run's bag, the same run with /battery_state recorded under another type, and the goals."""
    goals: list[bytes] = []

    def run(robot: BoundSimulator) -> None:
        step = lambda: time.sleep(0.02)  # noqa: E731 - distinct record times
        robot.publish("nav2", "/battery_state", {"percentage": 0.9, "power_supply_status": 1})
        step()
        robot.send_goal("nav2", "navigate")  # navigator still unconfigured: the model forbids it
        goals.append(robot.sent[("nav2", "navigate")])
        step()
        robot.finish("nav2", "navigate", "success")
        for t in ("navigator_configured", "navigator_activated", "undock_robot.start",
                  "undock_robot.success.undocked"):
            step()
            robot.play("nav2", t, None)
        step()
        robot.send_goal("nav2", "navigate")
        goals.append(robot.sent[("nav2", "navigate")])
        step()
        robot.send_goal("nav2", "navigate")  # a second goal while the first runs
        goals.append(robot.sent[("nav2", "navigate")])
        step()
        robot.publish("nav2", "/battery_state", {"percentage": float("nan"), "power_supply_status": 2})
        step()
        robot.finish("nav2", "navigate", "success")
        step()
        robot.finish("nav2", "navigate", "success")
        step()
        robot.nodes[("nav2", "navigator")].transition(1)  # active -> errorprocessing -> unconfigured

    folder = tmp_path_factory.mktemp("drift")
    bag, wrong = folder / "mcap", folder / "wrong"
    record(nav2, run, {bag: ("mcap", {}), wrong: ("sqlite3", {"/battery_state": "std_msgs/msg/Float32"})})
    return bag, wrong, goals


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_clean_run_conforms(clean, storage: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["conform", SYSTEM, str(clean[storage])]) == 0
    assert not logging.getLogger("skinet.bridge_ros2").disabled  # quiet while it replays only
    out = capsys.readouterr().out.splitlines()
    assert out[0].endswith(": 21 messages, 12 events, 0 model divergences")
    # the run ends before docking (the pilot docks in `skinet demo nav2`): the dock server's status is not in it;
    # the result of the aborted goal is not in a bag: its mode came from the binding's default, said so
    assert out[1:] == ["  not recorded: /dock_robot/_action/status", "  result not recorded: 1 (goals that ended with no result in the bag "
                       "(a rosbag records topics, and action results are services): their mode is the binding's "
                       "default)"]


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
@pytest.mark.parametrize("command", ["replay", "timeline"])
def test_a_bag_given_for_a_monitor_log_is_one_line_pointing_to_conform(
        clean, storage: str, command: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The folder, or its storage file: said to be a rosbag once, not one line per message (issue 32, item 8)."""
    bag = clean[storage]
    files = [p for p in bag.iterdir() if p.suffix in (".db3", ".mcap")]
    assert len(files) == 1
    for path in (bag, files[0]):
        assert main([command, str(path), *(["-o", str(bag / "t.png")] if command == "timeline" else [])]) == 1
        captured = capsys.readouterr()
        assert (captured.out, captured.err) == ("", f"{path}: error: this is a ROS 2 bag (rosbag2: CDR messages), "
                                                    "not a monitor log: `skinet conform SYSTEM BAG` checks a bag "
                                                    "against a model\n")


def test_a_drifting_run_reports_each_divergence_with_its_time(drifting, capsys: pytest.CaptureFixture[str]) -> None:
    bag, _, goals = drifting
    assert main(["conform", SYSTEM, str(bag), "--json"]) == 3
    report, = json.loads(capsys.readouterr().out)
    recorded = stamps(bag)
    start = recorded[0]
    assert [d["what"] for d in report["divergences"]] == [
        f"{NAV}: goal {goal_text(goals[0])} ACCEPTED: navigate started, but the model says navigate cannot start: "
        "precondition 'active' (navigator == Active) false (navigator is Unconfigured, motion is Still, dock is "
        "Docked, battery is Ok, charging is Charging)",
        f"{NAV}: goal {goal_text(goals[2])} ACCEPTED: a second goal of navigate, but navigate already runs goal "
        f"{goal_text(goals[1])} (one goal at a time per skill)",
        "/battery_state: percentage=nan: battery observed, but no state of battery matches",
        "/bt_navigator/transition_event: errorprocessing -> unconfigured (navigator Active -> Unconfigured): "
        "navigator became Unconfigured, but no event of the model takes navigator from Active to Unconfigured here",
    ]
    assert all(any(abs(d["stamp"] - s) < 1e-6 for s in recorded) for d in report["divergences"])  # record times
    assert [round(d["offset"], 6) for d in report["divergences"]] == [round(d["stamp"] - start, 6)
                                                                      for d in report["divergences"]]
    assert report["unrecorded"] == ["/dock_robot/_action/status", "/emergency_stop"]
    assert main(["conform", SYSTEM, str(bag)]) == 3
    text = capsys.readouterr().out.splitlines()
    assert text[0].endswith(": 20 messages, 12 events, 4 model divergences")  # 2 drifts moved nothing: events too
    assert text[1].startswith("  +") and " s (" in text[1] and text[1].endswith(
        "Z) nav2: " + report["divergences"][0]["what"])


def test_a_bag_recording_a_bound_topic_under_another_type(drifting, capsys: pytest.CaptureFixture[str]) -> None:
    _, bag, _ = drifting
    assert main(["conform", SYSTEM, str(bag)]) == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        f"{bag}: error: topic /battery_state is recorded as std_msgs/msg/Float32; the binding of nav2 reads it as "
        "sensor_msgs/msg/BatteryState"]


def test_missing_and_unreadable_bags(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["conform", SYSTEM, str(tmp_path / "none.mcap")]) == 1
    assert capsys.readouterr().err.strip() == f"{tmp_path / 'none.mcap'}: error: cannot read file: No such file or directory"
    (tmp_path / "junk.mcap").write_text("junk")
    assert main(["conform", SYSTEM, str(tmp_path / "junk.mcap")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"{tmp_path / 'junk.mcap'}: error: cannot replay: ")


def test_conform_a_manager_system_too(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without bindings it replays managers' statuses: an empty bag conforms."""
    from rosbags.rosbag2 import Writer

    with Writer(tmp_path / "empty", version=9):
        pass
    assert main(["conform", str(REPO / "skillsets" / "spot_arm.toml"), str(tmp_path / "empty")]) == 0
    assert capsys.readouterr().out.strip() == f"{tmp_path / 'empty'}: 0 messages, 0 events, 0 model divergences"


def test_a_bad_binding_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "nav2.rl").write_text((NAV2 / "nav2.rl").read_text())
    (tmp_path / "s.toml").write_text('[system]\nname = "s"\n[[skillsets]]\nmodel = "nav2.rl"\nbinding = "b.toml"\n')
    (tmp_path / "b.toml").write_text('[skills.navigat]\naction = "/navigate_to_pose"\n')
    with pytest.raises(SourceError):
        load_bindings(load_system(tmp_path / "s.toml")[0])
    assert main(["conform", str(tmp_path / "s.toml"), str(tmp_path / "none.mcap")]) == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        f"{tmp_path / 'b.toml'}:1:1: error: unknown skill 'navigat' of skillset 'nav2' (candidates: navigate)"]


def test_the_docs_show_what_conform_prints_on_the_example_bag(capsys: pytest.CaptureFixture[str],
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/robot.md's block after `skinet conform ... nav2_drift`, as the README's examples are checked
    (``...`` inside a line stands for any text)."""
    from tests.test_readme import matches

    monkeypatch.chdir(REPO)
    docs = (REPO / "docs" / "robot.md").read_text()
    block = docs.split("what the model expected, and exits 3 when there is one (0 when there is none):")[1]
    expected = tuple(line[3:] for line in block.split("```")[1].strip("\n").rstrip().splitlines())
    assert main(["conform", "examples/nav2/nav2.toml", "examples/nav2/bags/nav2_drift"]) == 3
    assert matches(expected, capsys.readouterr().out.splitlines())


def test_a_system_of_managers_and_bindings(clean, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Managers' topics go to the manager derivation, bound topics to the bindings', in one replay."""
    skillsets = REPO / "skillsets"
    (tmp_path / "mixed.toml").write_text(
        f'[system]\nname = "mixed"\ntypes = "{skillsets / "spot_arm.types.json"}"\n'
        f'[[skillsets]]\nmodel = "{skillsets / "spot.rl"}"\nmanager = "/spot/spot_skillset_manager"\n'
        f'[[skillsets]]\nmodel = "{NAV2 / "nav2.rl"}"\nbinding = "{NAV2 / "nav2.binding.toml"}"\n')
    assert main(["conform", str(tmp_path / "mixed.toml"), str(clean["mcap"])]) == 0
    assert capsys.readouterr().out.splitlines()[0].endswith(": 21 messages, 12 events, 0 model divergences")
