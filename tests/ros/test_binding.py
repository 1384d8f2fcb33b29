"""Binding files, message conditions and type definitions (docs/semantics.md §9; skinet.ros.binding, condition, definitions).

Every bad binding gives one error at the file, line and column of the key or value
at fault, with close names where a name is unknown.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.errors import Pos, SourceError
from skinet.system.load import load_bindings, load_system
from skinet.ros.binding import LIFECYCLE_STATES, first_samples, parse_binding, result_fields
from skinet.ros.condition import example_message, parse_condition
from skinet.ros.actions import message
from skinet.ros.definitions import action_types, build_store, rihs01
from skinet.ros.typestore import to_plain

REPO = Path(__file__).resolve().parents[2]
NAV2 = REPO / "examples" / "nav2"

FIBONACCI = "int32 order\n---\nint32[] sequence\n---\nint32[] partial_sequence\n"


@pytest.fixture(scope="module")
def nav2():
    system, _ = load_system(NAV2 / "nav2.toml")
    bindings, warnings = load_bindings(system)
    return system, bindings["nav2"], warnings


def error(call, *args, **kwargs) -> str:  # type: ignore[no-untyped-def]
    with pytest.raises(SourceError) as info:
        call(*args, **kwargs)
    assert len(info.value.diagnostics) == 1
    return str(info.value)


# ---- definitions -------------------------------------------------------------------------------


def test_service_and_action_hashes_are_those_ros_publishes() -> None:
    """REP 2011 hashes of services and action protocol types, against values published by ROS 2 Jazzy
    (rmw_zenoh keys carry them): AddTwoInts, CancelGoal, Fibonacci's SendGoal, GetResult, FeedbackMessage."""
    action = "action_tutorials_interfaces/action/Fibonacci"
    store = build_store({action: FIBONACCI, "example_interfaces/srv/AddTwoInts": "int64 a\nint64 b\n---\nint64 sum\n"})
    assert {n: rihs01(store, n)[7:15] for n in (
        "example_interfaces/srv/AddTwoInts", "action_msgs/srv/CancelGoal", f"{action}_SendGoal",
        f"{action}_GetResult", f"{action}_FeedbackMessage", "action_msgs/msg/GoalStatusArray")} == {
        "example_interfaces/srv/AddTwoInts": "e118de6b", "action_msgs/srv/CancelGoal": "573d8b0a",
        f"{action}_SendGoal": "a0603060", f"{action}_GetResult": "8b47e383", f"{action}_FeedbackMessage": "50fc26b9",
        "action_msgs/msg/GoalStatusArray": "6c1684b0"}
    assert action_types(store) == [action]
    assert [f for f, _ in store.fielddefs[f"{action}_SendGoal_Request"][1]] == ["goal_id", "goal"]
    assert [f for f, _ in store.fielddefs[f"{action}_GetResult_Response"][1]] == ["status", "result"]
    # An empty part (GetState's request, a feedback-less action) holds rosidl's placeholder field.
    assert store.fielddefs["lifecycle_msgs/srv/GetState_Request"][1][0][0] == "structure_needs_at_least_one_member"


@pytest.mark.parametrize("name,text,message", [
    ("pkg/action/Bad", "int32 a\n---\nint32 b\n", "a .action definition has 3 part(s) separated by '---' lines, "
                                                 "this one has 2"),
    ("pkg/srv/Bad", "int32 a\n", "a .srv definition has 2 part(s) separated by '---' lines, this one has 1"),
    ("pkg/action/lower", "---\n---\n", "'pkg/action/lower' is not a ROS 2 type name (package/msg|srv|action/Name)"),
    ("pkg/msg/Bad", "int32\n", "cannot read the definition of pkg/msg/Bad: Could not parse:"),
    ("pkg/action/Bad", "int32 a\n---\nint32 b\n---\nint32 c 1.5  # feedback\n",
     "5:9: error: cannot read the definition of pkg/action/Bad: the default of field c (int32): '1.5' is not an integer"),
    ("pkg/srv/Bad", "bool[] flags [true, maybe]\n---\n", "1:14: error: cannot read the definition of pkg/srv/Bad: "
                                                       "the default of field flags (bool[]): 'maybe' is not a bool"),
    ("pkg/msg/Bad", "float32 x abc\n", "1:11: error: cannot read the definition of pkg/msg/Bad: the default of field x "
                                       "(float32): 'abc' is not a number"),
])
def test_bad_definitions(name: str, text: str, message: str) -> None:
    got = error(build_store, {name: text}, {name: "defs/x"})
    assert got.startswith(f"defs/x:{message}" if message[0].isdigit() else f"defs/x: error: {message}"), got


def test_fields_take_their_definitions_defaults_and_a_quaternion_is_no_rotation() -> None:
    """rosbags drops a .msg field's default; rosidl, and so a goal the pilot sends, keeps it (docs/semantics.md §9).  The
    defaults leave REP 2011 hashes unchanged (rmw_zenoh keys), as ROS hashes definitions without them."""
    action = "pkg/action/Go"
    text = ("float32 max_time 30.0  # s\nbool use_id True\nstring name 'a # b'\nint32[] ids [1, 2]\nuint8[2] pair [3, 4]\n"
            "int8 LIMIT=5\ngeometry_msgs/PoseStamped pose\n---\nint32 code\n---\n")
    store = build_store({action: text})
    plain = to_plain(message(store, f"{action}_Goal", {"ids": [7]}))
    assert plain == {"max_time": 30.0, "use_id": True, "name": "a # b", "ids": [7], "pair": [3, 4],
                     "pose": {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
                              "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
                                       "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}}}
    bare = build_store({action: "float32 max_time\nbool use_id\nstring name\nint32[] ids\nuint8[2] pair\nint8 LIMIT=5\n"
                                "geometry_msgs/PoseStamped pose\n---\nint32 code\n---\n"})
    assert to_plain(message(bare, f"{action}_Goal", {}))["max_time"] == 0.0
    assert rihs01(store, f"{action}_SendGoal") == rihs01(bare, f"{action}_SendGoal")


# ---- conditions --------------------------------------------------------------------------------

BATTERY = "sensor_msgs/msg/BatteryState"


@pytest.mark.parametrize("text,msg,expected", [
    ("percentage < 0.2", {"percentage": 0.19}, True),
    ("percentage < 0.2", {"percentage": 0.2}, False),
    ("percentage >= .2 and present", {"percentage": 0.5, "present": False}, False),
    ("not present or percentage == 1", {"percentage": 1, "present": True}, True),
    ("power_supply_status == POWER_SUPPLY_STATUS_CHARGING", {"power_supply_status": 1}, True),
    ("power_supply_status != POWER_SUPPLY_STATUS_CHARGING", {"power_supply_status": 1}, False),
    ("header.frame_id == 'base_link'", {"header": {"frame_id": "base_link"}}, True),
    ("(temperature > -5.5) and (temperature <= 40)", {"temperature": -5.0}, True),
])
def test_conditions(text: str, msg: dict, expected: bool) -> None:
    assert parse_condition(text, BATTERY, build_store()).holds(msg) is expected


@pytest.mark.parametrize("text,message", [
    ("percentag < 0.2", "2:7: error: unknown field or constant 'percentag' of sensor_msgs/msg/BatteryState "
                        "(candidates: percentage, present)"),
    ("percentage", "2:7: error: 'percentage' is a number, not a condition: compare it (e.g. percentage == ...)"),
    ("header < 3", "2:7: error: 'header' is a message; a condition compares single values"),
    ("cell_voltage == 1", "2:7: error: 'cell_voltage' is an array; a condition compares single values"),
    ("location < 'x'", "2:16: error: '<' orders numbers only; texts compare with == or !="),
    ("percentage == 'x'", "2:18: error: '==' compares a number with a text"),
    ("percentage <", "2:19: error: unexpected end of input, expected one of:"),
    ("header.frame_id.x == 1", "2:23: error: 'header.frame_id' has no fields"),
])
def test_condition_errors_point_into_the_file(text: str, message: str) -> None:
    assert error(parse_condition, text, BATTERY, build_store(), "b.toml", Pos(2, 7)).startswith(f"b.toml:{message}")


# ---- bindings ----------------------------------------------------------------------------------


def test_the_nav2_binding(nav2) -> None:  # type: ignore[no-untyped-def]
    system, binding, warnings = nav2
    assert warnings == []
    assert [(s.skill, s.action, s.type, s.success.default, s.failure.default, [m for m, _ in s.failure.when])
            for s in binding.skills] == [
        ("navigate", "/navigate_to_pose", "nav2_msgs/action/NavigateToPose", "arrived", "failed", ["timed_out"]),
        ("dock_robot", "/dock_robot", "opennav_docking_msgs/action/DockRobot", "docked", "failed", ["not_charging"]),
        ("undock_robot", "/undock_robot", "opennav_docking_msgs/action/UndockRobot", "undocked", "failed", []),
    ]
    navigator = binding.resources[0]
    assert (navigator.lifecycle, navigator.states) == ("/bt_navigator", tuple(
        (s.capitalize(), i) for s, i in LIFECYCLE_STATES.items()))
    assert binding.topics() == {
        "/navigate_to_pose/_action/status": "action_msgs/msg/GoalStatusArray",
        "/dock_robot/_action/status": "action_msgs/msg/GoalStatusArray",
        "/undock_robot/_action/status": "action_msgs/msg/GoalStatusArray",
        "/bt_navigator/transition_event": "lifecycle_msgs/msg/TransitionEvent",
        "/battery_state": BATTERY, "/emergency_stop": "std_msgs/msg/Bool"}
    timed_out = binding.skills[0].failure
    assert timed_out.mode({"error_code": 9003}) == "timed_out" and timed_out.mode({"error_code": 9000}) == "failed"
    assert timed_out.mode(None) == "failed"


NAV2_MODEL = (NAV2 / "nav2.rl").read_text()
GOOD = """\
[binding]
definitions = "interfaces"

[skills.navigate]
action = "/navigate_to_pose"
type = "nav2_msgs/action/NavigateToPose"
failure = "failed"
"""


def check(tmp_path: Path, binding: str, files: dict[str, str] | None = None) -> str:
    """The one-line error of ``skinet parse``-like loading of a nav2 system with this binding."""
    (tmp_path / "nav2.rl").write_text(NAV2_MODEL)
    (tmp_path / "nav2.props").write_text("")
    (tmp_path / "s.toml").write_text('[system]\nname = "s"\nproperties = "nav2.props"\n'
                                     '[[skillsets]]\nmodel = "nav2.rl"\nbinding = "b.toml"\n')
    for name, text in {"interfaces/nav2_msgs/action/NavigateToPose.action":
                       (NAV2 / "interfaces/nav2_msgs/action/NavigateToPose.action").read_text(), **(files or {})}.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    (tmp_path / "b.toml").write_text(binding)
    try:  # the system reads the binding's commanded resources (its TOML too); the bridge the rest
        system, _ = load_system(tmp_path / "s.toml")
    except SourceError as exc:
        return str(exc).replace(str(tmp_path) + "/", "")
    return error(load_bindings, system).replace(str(tmp_path) + "/", "")


@pytest.mark.parametrize("text,message", [
    (GOOD.replace('type = "nav2_msgs/action/NavigateToPose"', 'type = "nav2_msgs/action/NavigateToPoze"'),
     "b.toml:6:9: error: unknown action type 'nav2_msgs/action/NavigateToPoze' (candidates: "
     "nav2_msgs/action/NavigateToPose); put its .action file in the binding's definitions folder as "
     "<package>/action/<Name>.action"),
    (GOOD.replace("[skills.navigate]", "[skills.navigat]"),
     "b.toml:4:1: error: unknown skill 'navigat' of skillset 'nav2' (candidates: navigate)"),
    (GOOD.replace("action = ", "actoin = "),
     "b.toml:5:1: error: unknown key 'actoin' in [skills.navigate] (candidates: action)"),
    (GOOD.replace('failure = "failed"', 'failure = "fail"'),
     "b.toml:7:12: error: unknown failure mode 'fail' of skill 'navigate' (candidates: failed)"),
    (GOOD.replace('failure = "failed"\n', ''),
     "b.toml:4:1: error: skill 'navigate' has several failure modes ('failed', 'timed_out'): name the mode of an "
     'ABORTED goal with failure = "..."'),
    (GOOD + 'failure_when = { timed_out = "error_code == TIMEOUTS" }\n',
     "b.toml:8:45: error: unknown field or constant 'TIMEOUTS' of nav2_msgs/action/NavigateToPose_Result "
     "(candidates: TIMEOUT)"),
    (GOOD + 'failure_when = { blocked = "error_code == 1" }\n',
     "b.toml:8:18: error: unknown failure mode 'blocked' of skill 'navigate' (expected one of: failed, timed_out)"),
    (GOOD + '[resources.battery]\ntopic = "/battery_state"\ntype = "sensor_msgs/msg/BatteryState"\n'
            'states = { Lo = "percentage < 0.2" }\n',
     "b.toml:11:12: error: unknown state 'Lo' of resource 'battery' (candidates: Low)"),
    (GOOD + '[resources.battery]\ntopic = "/battery_state"\ntype = "sensor_msgs/msg/BatteryStat"\n'
            'states = { Low = "percentage < 0.2" }\n',
     "b.toml:10:9: error: unknown message type 'sensor_msgs/msg/BatteryStat' (candidates: "
     "sensor_msgs/msg/BatteryState, "),
    (GOOD + '[resources.battery]\ntopic = "/battery_state"\ntype = "sensor_msgs/msg/BatteryState"\n'
            'states = { Low = "percent < 0.2" }\n',
     "b.toml:11:19: error: unknown field or constant 'percent' of sensor_msgs/msg/BatteryState "
     "(candidates: percentage, present)"),
    (GOOD + '[resources.navigator]\nlifecycle = "/bt_navigator"\nstates = { Active = "activ" }\n',
     "b.toml:10:22: error: unknown lifecycle state 'activ' (candidates: active, inactive)"),
    (GOOD + '[resources.dock]\nlifecycle = "/docking_server"\n',
     "b.toml:8:1: error: [resources.dock] needs 'states': model state = lifecycle state "
     "(unconfigured, inactive, active, finalized)"),
    (GOOD + '[resources.navigator]\ntopic = "/x"\nlifecycle = "/bt_navigator"\n',
     "b.toml:8:1: error: [resources.navigator] needs either 'lifecycle' (a lifecycle node) or 'topic'"),
    (GOOD + '[events.estop]\ntopic = "/emergency_stop"\ntype = "std_msgs/msg/Bool"\nwhen = "data"\n',
     "b.toml:8:1: error: unknown event 'estop' of skillset 'nav2' (expected one of: navigator_configured, "
     "navigator_activated, navigator_deactivated, navigator_cleaned_up, navigator_shut_down, battery_low, "
     "battery_recharged, charging_started, charging_stopped, emergency_stop)"),
    (GOOD + '[events.emergency_stop]\ntopic = "/battery_state"\ntype = "std_msgs/msg/Bool"\nwhen = "data"\n'
            '[resources.battery]\ntopic = "/battery_state"\ntype = "sensor_msgs/msg/BatteryState"\n'
            'states = { Low = "percentage < 0.2" }\n',
     "b.toml:10:9: error: topic /battery_state is bound as sensor_msgs/msg/BatteryState in [resources.battery] and "
     "as std_msgs/msg/Bool here"),
    (GOOD + '[resources.navigator]\nlifecycle = "/bt_navigator"\ncommanded = "yes"\n',
     "b.toml:10:14: error: [resources.navigator] commanded must be true or false, not 'yes'"),
    (GOOD + '[resources.navigator]\nlifecycle = "/bt_navigator"\ncommandd = true\n',
     "b.toml:10:1: error: unknown key 'commandd' in [resources.navigator] (candidates: commanded)"),
    (GOOD + '[resources.dock]\ntopic = "/docked"\ntype = "std_msgs/msg/Bool"\n'
            'states = { Docked = "data", Undocked = "not data" }\ncommanded = true\n',
     "b.toml:12:13: error: [resources.dock] commanded = true, but no event of skillset 'nav2' changes dock: only "
     "events can be commanded"),
    (GOOD + '[resources.navigator]\nlifecycle = "/bt_navigator"\ncommanded = true\n'
            '[events.navigator_activated]\ntopic = "/active"\ntype = "std_msgs/msg/Bool"\nwhen = "data"\n',
     "b.toml:11:1: error: [events.navigator_activated] binds event 'navigator_activated' to a topic condition (the "
     "robot's own), but it changes navigator, which [resources.navigator] says is commanded"),
    (GOOD.replace('action = "/navigate_to_pose"', 'action = "navigate to pose"'),
     "b.toml:5:11: error: 'navigate to pose' is not a ROS 2 name (e.g. /navigate_to_pose)"),
    ("[binding]\nskillset = \"base\"\n", "b.toml:2:13: error: this binding is for skillset 'base', the system file "
                                         "gives it to 'nav2'"),
    ("[binding]\n", "b.toml: error: the binding binds nothing: add [skills.<skill>], [resources.<resource>] or "
                    "[events.<event>] tables"),
    ('[binding]\ndefinitions = "nowhere"\n', "b.toml: error: definitions folder nowhere is not a folder"),
    ("[skills]\nnavigate = 3\n", "b.toml:2:12: error: [skills.navigate] must be a table"),
    ("[skills.navigate\n", "b.toml:1:17: error: invalid TOML: Expected ']' at the end of a table declaration"),
])
def test_bad_bindings_give_one_line_at_the_fault(tmp_path: Path, text: str, message: str) -> None:
    assert check(tmp_path, text).startswith(message)


def test_a_skill_without_a_binding_is_a_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "nav2.rl").write_text(NAV2_MODEL)
    (tmp_path / "b.toml").write_text('[resources.navigator]\nlifecycle = "/bt_navigator"\n')
    system, _ = load_system(_system_file(tmp_path))
    binding = parse_binding((tmp_path / "b.toml").read_text(), "b.toml", system.component("nav2").skillset)
    assert [str(w) for w in binding.warnings] == [
        f"b.toml: warning: skill '{k}' has no binding: the bridge never sees it run"
        for k in ("navigate", "dock_robot", "undock_robot")]


def _system_file(tmp_path: Path) -> Path:
    path = tmp_path / "s.toml"
    path.write_text('[system]\nname = "s"\n[[skillsets]]\nmodel = "nav2.rl"\nbinding = "b.toml"\n')
    return path


def test_the_first_samples_show_the_initial_states_and_fire_no_event(nav2) -> None:  # type: ignore[no-untyped-def]
    """A simulated robot's first /battery_state: battery Ok (percentage >= 0.2) and Charging at once; its first
    /emergency_stop does not fire the event (data false)."""
    system, binding, _ = nav2
    skillset = system.component("nav2").skillset
    samples = first_samples(binding, skillset)
    assert samples == {"/battery_state": {"percentage": 0.2, "power_supply_status": 1},
                       "/emergency_stop": {"data": False}}
    battery = {r.resource: dict(r.states) for r in binding.resources if r.topic == "/battery_state"}
    plain = to_plain(message(binding.store, BATTERY, samples["/battery_state"]))
    assert [state for r in ("battery", "charging") for state, c in battery[r].items() if c.holds(plain)] == [
        "Ok", "Charging"]


def test_a_users_own_binding_gets_first_samples_too(tmp_path: Path) -> None:
    """Another robot's battery: Ok when the voltage is high enough and the battery present; its own stop button
    (an event on a nested field) not pressed."""
    (tmp_path / "nav2.rl").write_text(NAV2_MODEL)
    (tmp_path / "b.toml").write_text(
        '[resources.battery]\ntopic = "/power"\ntype = "sensor_msgs/msg/BatteryState"\n'
        'states = { Ok = "voltage >= 11.5 and present", Low = "voltage < 11.5 or not present" }\n'
        '[events.emergency_stop]\ntopic = "/stop"\ntype = "std_msgs/msg/Header"\nwhen = "frame_id == \'stop\'"\n')
    system, _ = load_system(_system_file(tmp_path))
    binding = parse_binding((tmp_path / "b.toml").read_text(), "b.toml", system.component("nav2").skillset)
    assert first_samples(binding, system.component("nav2").skillset) == {
        "/power": {"voltage": 11.5, "present": True}, "/stop": {"frame_id": ""}}


def test_a_topic_whose_initial_state_no_message_shows_is_named(tmp_path: Path) -> None:
    (tmp_path / "nav2.rl").write_text(NAV2_MODEL)
    (tmp_path / "b.toml").write_text('[resources.battery]\ntopic = "/battery_state"\ntype = "sensor_msgs/msg/BatteryState"'
                                     '\nstates = { Ok = "percentage > 1 and percentage < 0", Low = "percentage < 0.2" }\n')
    system, _ = load_system(_system_file(tmp_path))
    binding = parse_binding((tmp_path / "b.toml").read_text(), "b.toml", system.component("nav2").skillset)
    with pytest.raises(ValueError) as info:
        first_samples(binding, system.component("nav2").skillset)
    assert str(info.value) == "b.toml: no /battery_state message found that shows battery Ok"


def test_a_result_names_the_mode_it_is_asked_for(nav2) -> None:  # type: ignore[no-untyped-def]
    """What a simulated action server answers for a goal that ends in a mode: fields the binding's conditions read
    as that mode (the default: none of them true), read back by the binding as the same mode."""
    _, binding, _ = nav2
    dock = binding.skill("dock_robot")
    assert result_fields(dock, "failure", "not_charging", binding.store) == {"error_code": 906}
    assert result_fields(dock, "failure", "failed", binding.store) == {"error_code": 0}
    assert result_fields(dock, "failure", "", binding.store) == {"error_code": 0}  # '': the default mode
    assert result_fields(dock, "success", "docked", binding.store) == {}
    assert result_fields(dock, "failure", "docked", binding.store) is None  # not a failure mode
    for mode in ("not_charging", "failed"):
        plain = to_plain(message(binding.store, f"{dock.type}_Result", result_fields(dock, "failure", mode,
                                                                                    binding.store)))
        assert dock.failure.mode(plain) == mode


def test_an_example_message_steps_around_the_values_compared() -> None:
    store = build_store()
    below = parse_condition("percentage < 0.2", BATTERY, store)
    status = parse_condition("power_supply_status != POWER_SUPPLY_STATUS_UNKNOWN", BATTERY, store)
    header = parse_condition("header.frame_id == 'map'", BATTERY, store)
    assert example_message([(below, True), (status, True)], store) == {"percentage": 0.0, "power_supply_status": 1}
    assert example_message([(below, False)], store) == {"percentage": 0.2}
    assert example_message([(header, True)], store) == {"header": {"frame_id": "map"}}
    assert example_message([(header, False)], store) == {"header": {"frame_id": ""}}
    # An unsigned field is never tried below 0: no status "below UNKNOWN" exists.
    lowest = parse_condition("power_supply_status < POWER_SUPPLY_STATUS_UNKNOWN", BATTERY, store)
    assert example_message([(lowest, True)], store) is None
    assert example_message([], store) == {}


def test_docstring_examples() -> None:
    import doctest

    import skinet.ros.condition
    assert doctest.testmod(skinet.ros.condition).failed == 0


DOCK = GOOD + """\
[skills.dock_robot]
action = "/dock_robot"
type = "opennav_docking_msgs/action/DockRobot"
failure = "failed"
"""
DOCK_FILES = {"interfaces/opennav_docking_msgs/action/DockRobot.action":
              (NAV2 / "interfaces/opennav_docking_msgs/action/DockRobot.action").read_text()}
DOCK_GOAL = "opennav_docking_msgs/action/DockRobot_Goal"


@pytest.mark.parametrize("text,message", [
    (DOCK, f"b.toml:8:1: error: input 'dock' of skill 'dock_robot' reaches no field of {DOCK_GOAL}: map it with "
           'inputs = { dock = "<field>" } (fields: use_dock_id, dock_id, dock_pose, dock_type, max_staging_time, '
           "navigate_to_staging_pose)"),
    (DOCK + 'inputs = { dock = "dock_idd" }\n',
     f"b.toml:12:20: error: unknown field 'dock_idd' of {DOCK_GOAL} (candidates: dock_id, use_dock_id)"),
    (DOCK + 'inputs = { dok = "dock_id" }\n',
     "b.toml:12:12: error: unknown input 'dok' of skill 'dock_robot' (candidates: dock)"),
    (DOCK + 'inputs = { dock = "dock_pose.pose.position.z.w" }\n',
     "b.toml:12:20: error: dock_pose.pose.position.z is not a message: it has no field 'w'"),
    (DOCK + 'inputs = { dock = "dock_pose.pose.posiion" }\n',
     "b.toml:12:20: error: unknown field 'posiion' of geometry_msgs/msg/Pose (candidates: position)"),
    (DOCK + 'inputs = { dock = 3 }\n',
     "b.toml:12:19: error: [skills.dock_robot] inputs: the goal field of input 'dock' must be a field name such as "
     '"pose" or "pose.pose.position.x"'),
    (DOCK + 'inputs = { dock = "dock_id" }\ngoal = { dock_id = "home" }\n',
     "b.toml:13:10: error: goal field dock_id is fixed by [skills.dock_robot] goal and set by input 'dock': keep one"),
    (DOCK + 'inputs = { dock = "dock_id" }\ngoal = { use_dock_id = 1 }\n',
     "b.toml:13:24: error: [skills.dock_robot] goal: expected bool at use_dock_id, got an integer"),
    (DOCK + 'inputs = { dock = "dock_id" }\ngoal = { dock_pose = { pose = { position = { x = "far" } } } }\n',
     "b.toml:13:22: error: [skills.dock_robot] goal: expected float64 at dock_pose.pose.position.x, got a string"),
    (DOCK + 'inputs = { dock = "dock_id" }\ngoal = { use_dockid = true }\n',
     f"b.toml:13:10: error: unknown field 'use_dockid' of {DOCK_GOAL} (candidates: use_dock_id, dock_id)"),
    (DOCK + 'inputs = { dock = "dock_id" }\ngoal = 3\n',
     "b.toml:13:8: error: [skills.dock_robot] goal must be a table"),
])
def test_bad_goal_mappings_give_one_line_at_the_fault(tmp_path: Path, text: str, message: str) -> None:
    """What a pilot's start sends (docs/semantics.md §9, Acting): every input reaches a goal field, fixed fields type-check."""
    assert check(tmp_path, text, DOCK_FILES) == message


def test_a_start_s_goal_fields_from_the_plan_s_inputs(nav2) -> None:  # type: ignore[no-untyped-def]
    _, binding, _ = nav2
    dock = binding.skill("dock_robot")
    assert (dock.inputs, dock.goal) == ((("dock", ("dock_id",)),), {"use_dock_id": True})
    assert dock.goal_fields({"dock": "home"}) == {"use_dock_id": True, "dock_id": "home"}
    assert dock.goal_fields({}) == {"use_dock_id": True}
    assert binding.skill("navigate").goal_fields({}) == {}
    with pytest.raises(KeyError, match="'target' is not an input of dock_robot"):
        dock.goal_fields({"target": 1})
