"""Loading system, model and state files: bad files give one clear error, and
states the robot cannot be in are refused unless asked for (docs/semantics.md §3)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import msgpack
import pytest

from skinet_cli.main import main
from skinet.errors import SourceError
from skinet.system.load import load_goals, load_model, load_state, load_system, load_typemap
from skinet.system.model import marking_problems

ROOT = Path(__file__).resolve().parents[1]
SYSTEM = ROOT / "skillsets" / "spot_arm.toml"

TWO = """\
skillset alpha { resource r { state { A B } initial A transition all } skill k { start r -> B } }
skillset beta { resource q { state { X Y } initial X transition all } event e { effect q -> Y } }
"""


def error(call, *args) -> str:  # type: ignore[no-untyped-def]
    with pytest.raises(SourceError) as info:
        call(*args)
    return str(info.value)


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ---- system files -------------------------------------------------------------------------


def test_one_model_file_with_two_skillsets(tmp_path: Path) -> None:
    write(tmp_path, "two.rl", TWO)
    whole = write(tmp_path, "whole.toml", '[system]\nname = "w"\n[[skillsets]]\nmodel = "two.rl"\n')
    system, warnings = load_system(whole)
    assert [(c.name, c.manager) for c in system.components] == [("alpha", ""), ("beta", "")] and warnings == []
    picked = write(
        tmp_path, "picked.toml",
        '[system]\nname = "p"\n[[skillsets]]\nmodel = "two.rl"\nname = "beta"\nmanager = "/b/mgr"\n'
        '[[skillsets]]\nmodel = "two.rl"\nname = "alpha"\nmanager = "/a/mgr"\n',
    )
    system, _ = load_system(picked)
    assert [(c.name, c.manager) for c in system.components] == [("beta", "/b/mgr"), ("alpha", "/a/mgr")]


def test_one_model_file_with_two_skillsets_errors(tmp_path: Path) -> None:
    write(tmp_path, "two.rl", TWO)
    bad = write(tmp_path, "bad.toml", '[system]\nname = "b"\n[[skillsets]]\nmodel = "two.rl"\nmanager = "/m"\n')
    assert error(load_system, bad) == (
        f"{bad}: error: skillsets entry 1: two.rl declares 2 skillsets ('alpha', 'beta');"
        " give one entry per skillset, each with its 'name' and 'manager'"
    )
    gamma = write(tmp_path, "g.toml", '[system]\nname = "g"\n[[skillsets]]\nmodel = "two.rl"\nname = "gamma"\n')
    assert error(load_system, gamma) == f"{gamma}: error: skillsets entry 1 names 'gamma' but two.rl declares 'alpha', 'beta'"
    twice = write(tmp_path, "t.toml", '[system]\nname = "t"\n[[skillsets]]\nmodel = "two.rl"\n[[skillsets]]\nmodel = "two.rl"\n')
    assert error(load_system, twice) == f"{tmp_path / 'two.rl'}:1:10: error: skillset 'alpha' appears twice in system 't'"


def test_a_skillset_bound_to_plain_ros2_names_its_binding_file(tmp_path: Path) -> None:
    """``binding`` (docs/semantics.md §9) is a path relative to the system file, instead of ``manager``."""
    write(tmp_path, "two.rl", TWO)
    path = write(tmp_path, "b.toml", '[system]\nname = "b"\n[[skillsets]]\nmodel = "two.rl"\nname = "alpha"\n'
                 'binding = "alpha.binding.toml"\n[[skillsets]]\nmodel = "two.rl"\nname = "beta"\nmanager = "/m"\n')
    assert error(load_system, path) == f"{tmp_path / 'alpha.binding.toml'}: error: cannot read file: No such file or " \
                                       "directory"  # it says which events are commanded (docs/semantics.md §9)
    write(tmp_path, "alpha.binding.toml", "")
    system, _ = load_system(path)
    assert [(c.name, c.manager, c.binding) for c in system.components] == [
        ("alpha", "", str(tmp_path / "alpha.binding.toml")), ("beta", "/m", "")]
    both = write(tmp_path, "x.toml", '[system]\nname = "x"\n[[skillsets]]\nmodel = "two.rl"\nname = "alpha"\n'
                 'manager = "/m"\n  binding = "a.toml"\n')
    assert error(load_system, both) == (f"{both}:7:3: error: [[skillsets]] entry 1: give 'manager' (a skillset "
                                        "manager) or 'binding' (plain ROS 2 interfaces), not both")
    number = write(tmp_path, "n.toml", '[system]\nname = "n"\n[[skillsets]]\nmodel = "two.rl"\nname = "beta"\n'
                   '[[skillsets]]\nmodel = "two.rl"\nname = "alpha"\nbinding = 3\n')
    assert error(load_system, number) == f"{number}:9:1: error: [[skillsets]] entry 2 'binding' must be a string, not 3"
    whole = write(tmp_path, "w.toml", '[system]\nname = "w"\n[[skillsets]]\nmodel = "two.rl"\nbinding = "a.toml"\n')
    assert error(load_system, whole).startswith(f"{whole}: error: skillsets entry 1: two.rl declares 2 skillsets")


def test_two_skillset_file_travels_to_the_predictor(tmp_path: Path) -> None:
    from skinet.wire.convert import bundle, system_from_bundle

    write(tmp_path, "two.rl", TWO)
    path = write(tmp_path, "s.toml", '[system]\nname = "w"\n[[skillsets]]\nmodel = "two.rl"\n')
    system, _ = load_system(path)
    rebuilt = system_from_bundle(bundle(system))
    assert [c.name for c in rebuilt.components] == ["alpha", "beta"]
    assert bundle(rebuilt).digest == bundle(system).digest
    # Picked by name, in another order, or only one of the two.
    for picked in (["beta", "alpha"], ["beta"]):
        entries = "".join(f'[[skillsets]]\nmodel = "two.rl"\nname = "{n}"\nmanager = "/{n}"\n' for n in picked)
        path = write(tmp_path, "p.toml", '[system]\nname = "p"\n' + entries)
        system, _ = load_system(path)
        b = bundle(system)
        assert [e[0] for e in b.skillsets] == [f"two.rl#{n}" for n in picked]
        rebuilt = system_from_bundle(b)
        assert [(c.name, c.manager) for c in rebuilt.components] == [(n, f"/{n}") for n in picked]
        assert bundle(rebuilt).digest == b.digest


def test_commanded_events_travel_to_the_predictor() -> None:
    """A binding's commanded events (docs/semantics.md §9) are in the model bundle, so the predictor's rebuilt system has the
    same controllable transitions; a system without any keeps its digest's form (no field, nothing hashed)."""
    from skinet.wire.codec import decode, encode
    from skinet.wire.convert import bundle, system_from_bundle
    from skinet.wire.messages import ModelBundle

    nav2, _ = load_system(ROOT / "examples" / "nav2" / "nav2.toml")
    b = decode(encode(bundle(nav2)), ModelBundle)
    assert b.commanded == {"nav2": ["navigator_activated", "navigator_cleaned_up", "navigator_configured",
                                    "navigator_deactivated", "navigator_shut_down"]}
    rebuilt = system_from_bundle(b)
    assert bundle(rebuilt).digest == b.digest
    assert [(t.name, t.controllable) for t in rebuilt.component("nav2").net.transitions] == [
        (t.name, t.controllable) for t in nav2.component("nav2").net.transitions]
    without = b.model_copy(update={"commanded": {}})
    assert not any(t.controllable for t in system_from_bundle(without).component("nav2").net.transitions
                   if t.kind == "event")
    paper, _ = load_system(ROOT / "skillsets" / "spot_arm.toml")
    assert "commanded" not in msgpack.unpackb(encode(bundle(paper)))
    bad = b.model_copy(update={"commanded": {"nav2": ["navigator_flown"], "arm": ["x"]}})
    assert error(system_from_bundle, bad) == ("<model bundle>: error: commanded events name what skillset 'nav2' "
                                              "does not declare: navigator_flown")


def test_explore_accepts_a_two_skillset_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write(tmp_path, "two.rl", TWO)
    system = write(tmp_path, "s.toml", '[system]\nname = "w"\n[[skillsets]]\nmodel = "two.rl"\n')
    assert main(["explore", str(system), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["system"], report["complete"], report["markings"]) == ("w", True, 6)  # 3 x 2


@pytest.mark.parametrize(
    "text, message",
    [
        ('[system]\nname = "x"\n[[skillsets]]\nmodel = ', "invalid TOML: Invalid value", ),
        ('[system]\nname = "x\n', "invalid TOML: Illegal character '\\n'"),
        ('[system]\nname = "x"\ntitle = """never closed\n\n', "invalid TOML: Unterminated string"),
    ],
)
def test_toml_errors_have_a_position(tmp_path: Path, text: str, message: str) -> None:
    path = write(tmp_path, "s.toml", text)
    got = error(load_system, path)
    assert got.startswith(f"{path}:") and got.endswith(message)
    line, column = (int(x) for x in got[len(str(path)) + 1:].split(":")[:2])
    assert line >= 2 and column >= 1


@pytest.mark.parametrize(
    "text, where",
    [
        ('[system]\nname = "x"\n[[skillsets]]\nmodel = ', "4:8: error: invalid TOML: Invalid value"),
        ('[system]\nname = "x"\nmodel = "a.rl', "3:14: error: invalid TOML: Unterminated string"),
        ('[system]\nname = "x"\nt = [1,\n  2\n\n', "4:4: error: invalid TOML: Unclosed array"),
    ],
)
def test_toml_error_at_end_of_document(tmp_path: Path, text: str, where: str) -> None:
    # tomllib says "at end of document": the position is just after the last character.
    path = write(tmp_path, "s.toml", text)
    assert error(load_system, path) == f"{path}:{where}"


@pytest.mark.parametrize("nest", ["[" * 3000, "{a = " * 3000])
def test_deeply_nested_toml(tmp_path: Path, nest: str) -> None:
    path = write(tmp_path, "s.toml", f'[system]\nname = "x"\ndeep = {nest}\n')
    assert error(load_system, path) == f"{path}: error: invalid TOML: nested too deeply"
    assert error(load_typemap, path) == f"{path}: error: invalid TOML: nested too deeply"


def test_file_too_large(tmp_path: Path) -> None:
    path = tmp_path / "huge.toml"
    with open(path, "wb") as f:
        f.truncate(10 * 2**20)  # 10 MiB, refused before it is read
    assert error(load_system, path) == f"{path}: error: file too large: 10485760 bytes (the limit is 262144)"


# ---- state files ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def system():  # type: ignore[no-untyped-def]
    return load_system(SYSTEM)[0]


@pytest.mark.parametrize(
    "data, message",
    [
        ("[" * 100_000, "invalid JSON: nested too deeply"),
        ({"spot": {"running": [["teleop"]]}}, "'running' of 'spot' must list skill names, not a list"),
        ({"spot": {"running": [{"skill": "teleop"}]}}, "'running' of 'spot' must list skill names, not an object"),
        ({"spot": {"running": [3]}}, "'running' of 'spot' must list skill names, not a number"),
        ({"spot": {"resources": {"posture": ["Standing"]}}},
         "state of resource 'spot:posture' must be a string, not a list"),
    ],
)
def test_malformed_state_files(tmp_path: Path, system, data: object, message: str) -> None:  # type: ignore[no-untyped-def]
    path = write(tmp_path, "state.json", data if isinstance(data, str) else json.dumps(data))
    assert error(load_state, path, system) == f"{path}: error: {message}"


UNSTABLE = {"spot": {"running": ["teleop"]}}  # a powered-off, sitting spot running teleop
UNREACHABLE = {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing"}, "running": ["teleop"]}}
REACHABLE = {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"},
                      "running": ["teleop"]}}
NOT_STABLE = ("'spot' is not stable: invariant violated (teleop.inv.powered, teleop.inv.upright);"
              " the manager never publishes such a state")
NOT_REACHABLE = ("'spot' is not reachable: no sequence of transitions (events included)"
                 " leads there from its initial marking")


def test_impossible_states_are_refused(tmp_path: Path, system) -> None:  # type: ignore[no-untyped-def]
    for data, reason in ((UNSTABLE, NOT_STABLE), (UNREACHABLE, NOT_REACHABLE)):
        path = write(tmp_path, "state.json", json.dumps(data))
        assert error(load_state, path, system) == (
            f"{path}: error: impossible state: {reason} (use --what-if to analyse it anyway)"
        )
        marking = load_state(path, system, what_if=True)
        assert marking_problems(system, marking) == [reason]
    path = write(tmp_path, "state.json", json.dumps(REACHABLE))
    assert marking_problems(system, load_state(path, system)) == []


def test_two_running_skills_of_a_powered_off_spot(tmp_path: Path, system) -> None:  # type: ignore[no-untyped-def]
    path = write(tmp_path, "state.json", json.dumps({"spot": {"running": ["teleop", "go_to_waypoint"]}}))
    assert "invariant violated (go_to_waypoint.inv.powered, go_to_waypoint.inv.upright," in error(load_state, path, system)


@pytest.mark.parametrize("command", [["unsafe", "--no-predict"], ["explore"], ["ctl", "AG true"]])
def test_what_if_option(tmp_path: Path, capsys: pytest.CaptureFixture[str], command: list[str]) -> None:
    path = str(write(tmp_path, "state.json", json.dumps(UNREACHABLE)))
    argv = [command[0], str(SYSTEM), "--state", path, "--budget", "5", *command[1:]]
    assert main(argv) == 1
    assert capsys.readouterr().err == (
        f"{path}: error: impossible state: {NOT_REACHABLE} (use --what-if to analyse it anyway)\n"
    )
    assert main([*argv, "--what-if"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"what-if analysis: {NOT_REACHABLE}\n")
    assert main([*argv, "--what-if", "--json"]) == 0
    captured = capsys.readouterr()
    json.loads(captured.out)  # the JSON stays clean; the note goes to standard error
    assert f"what-if analysis: {NOT_REACHABLE}\n" in captured.err


# ---- include (rl_model, Nov. 2023 to Feb. 2024) ----------------------------------------------


def test_include(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "lib").mkdir()
    write(tmp_path, "lib/types.rl", "type Pose\ntype { Float }\n")
    write(tmp_path, "lib/arm.rl", 'include "types.rl"\nskillset arm { data pose: Pose\n'
          "  resource r { state { A B } initial A transition all } skill k { input f: Float start r -> B } }\n")
    main_rl = write(tmp_path, "robot.rl", 'include "lib/arm.rl"\ninclude "lib/types.rl"\n'
                    "skillset base { data p: Pose resource q { state { X } initial X } }\n")
    model = load_model(main_rl)
    assert [s.name for s in model.skillsets] == ["base", "arm"] and model.warnings == ()
    assert [s.source for s in model.skillsets] == [str(main_rl), str(tmp_path / "lib/arm.rl")]
    system = write(tmp_path, "s.toml", '[system]\nname = "r"\n[[skillsets]]\nmodel = "robot.rl"\n')
    loaded, _ = load_system(system)
    assert list(loaded.sources) == ["robot.rl", "arm.rl"]
    assert main(["parse", str(main_rl)]) == 0
    assert "skillset arm (" in capsys.readouterr().out


def test_include_errors(tmp_path: Path) -> None:
    missing = write(tmp_path, "m.rl", 'type T\ninclude "nowhere.rl"\nskillset s {}\n')
    assert error(load_model, missing) == f"{missing}:2:9: error: cannot include 'nowhere.rl': cannot read file: No such file or directory"
    write(tmp_path, "bad.rl", "skillset s { data x: Undeclared\n  oops }\n")
    including = write(tmp_path, "i.rl", 'include "bad.rl"\n')
    assert error(load_model, including) == (  # the position, never the text of an included file
        f"{tmp_path / 'bad.rl'}:2:3: error: unexpected text (not quoted from an included file),"
        " expected one of: 'data', 'event', 'period', 'resource', 'skill', '}'"
    )
    write(tmp_path, "dup.rl", "skillset s {}\n")
    twice = write(tmp_path, "t.rl", 'include "dup.rl"\nskillset s {}\n')
    assert error(load_model, twice) == f"{tmp_path / 'dup.rl'}:1:10: error: duplicate skillset 's' (first declared at {twice}:2:10)"


def test_include_stays_in_the_models_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """No include reads outside the model's folder, and none echoes what a file holds (issue 25, item 6)."""
    monkeypatch.setenv("MODEL_TEST_TOKEN", "s3cr3t-token")
    monkeypatch.delenv("SKINET_INCLUDE_ROOT", raising=False)
    (tmp_path / "models").mkdir()
    write(tmp_path, "token.txt", "s3cr3t-token\n")
    outside = "it lies outside {} (included files stay in the model's folder, or in $SKINET_INCLUDE_ROOT)"
    root = tmp_path / "models"
    for name, target in [("/proc/self/environ", "/proc/self/environ"), ("../token.txt", str(tmp_path / "token.txt"))]:
        rl = write(tmp_path, "models/m.rl", f'include "{name}"\nskillset s {{}}\n')
        message = error(load_model, rl)
        assert message == f"{rl}:1:9: error: cannot include '{name}': " + outside.format(root), target
        assert "s3cr3t" not in message
        assert main(["parse", str(rl)]) == 1  # the command: that one line, no traceback
        assert capsys.readouterr().err == message + "\n"
    (root / "link.rl").symlink_to(tmp_path / "token.txt")  # a link out of the folder is outside too
    rl = write(tmp_path, "models/m.rl", 'include "link.rl"\nskillset s {}\n')
    assert error(load_model, rl) == f"{rl}:1:9: error: cannot include 'link.rl': " + outside.format(root)
    os.mkfifo(root / "pipe")  # would block a reader forever
    rl = write(tmp_path, "models/m.rl", 'include "pipe"\nskillset s {}\n')
    assert error(load_model, rl) == f"{rl}:1:9: error: cannot include 'pipe': not a regular file"
    # A configured root lets a model include from a shared folder; the text is still never quoted.
    monkeypatch.setenv("SKINET_INCLUDE_ROOT", str(tmp_path))
    rl = write(tmp_path, "models/m.rl", 'include "../token.txt"\nskillset s {}\n')
    assert error(load_model, rl) == (f"{tmp_path / 'models' / '../token.txt'}:1:1: error: unexpected text (not quoted "
                                     "from an included file), expected one of: 'skillset', 'type', end of input")
    (tmp_path / "bin.rl").write_bytes(b"\xffs3cr3t")
    rl = write(tmp_path, "models/m.rl", 'include "../bin.rl"\nskillset s {}\n')
    assert error(load_model, rl) == f"{rl}:1:9: error: cannot include '../bin.rl': cannot read file: not UTF-8 text (byte 0)"
    write(tmp_path, "types.rl", "type Pose\n")
    rl = write(tmp_path, "models/m.rl", 'include "../types.rl"\nskillset s { data p: Pose }\n')
    assert load_model(rl).warnings == ()
    assert error(load_model, rl, root).endswith(outside.format(root))  # the caller's root wins


def test_include_cycle(tmp_path: Path) -> None:
    write(tmp_path, "a.rl", 'include "b.rl"\nskillset a {}\n')
    write(tmp_path, "b.rl", 'include "a.rl"\nskillset b {}\n')
    assert [s.name for s in load_model(tmp_path / "a.rl").skillsets] == ["a", "b"]


def test_scenario_toml_errors() -> None:
    from skinet.mission.scenario import parse_scenario

    assert error(parse_scenario, "[scenario]\nname = ", "s.toml") == "s.toml:2:7: error: invalid TOML: Invalid value"
    assert error(parse_scenario, "a = " + "[" * 3000, "s.toml") == "s.toml: error: invalid TOML: nested too deeply"


def test_nul_in_a_path(tmp_path: Path) -> None:
    toml = write(tmp_path, "s.toml", '[system]\nname = "x"\n[[skillsets]]\nmodel = "a\\u0000b.rl"\n')
    assert error(load_system, toml) == f"{tmp_path / 'a'}\x00b.rl: error: cannot read file: embedded null byte"
    rl = write(tmp_path, "i.rl", 'include "a\x00b.rl"\nskillset s {}\n')
    assert error(load_model, rl) == f"{rl}:1:9: error: cannot include 'a\x00b.rl': cannot read file: embedded null byte"


def test_errors_echo_a_long_name_shortened(tmp_path: Path) -> None:
    """An include, model or binding name of 5 000 characters shows its first 200 (issue 31, item 5)."""
    long = "a" * 5000
    rl = write(tmp_path, "m.rl", f'include "{long}"\nskillset s {{}}\n')
    assert error(load_model, rl) == (f"{rl}:1:9: error: cannot include '{'a' * 200}… (5000 characters)': "
                                     "cannot read file: File name too long")
    write(tmp_path, "s.rl", "skillset s { resource r { state { A } initial A } }\n")
    toml = write(tmp_path, "s.toml", f'[system]\nname = "x"\n[[skillsets]]\nmodel = "s.rl"\nbinding = "{long}"\n')
    path = str(tmp_path / long)
    assert error(load_system, toml) == f"{path[:200]}… ({len(path)} characters): error: cannot read file: File name too long"
    toml = write(tmp_path, "s.toml", f'[system]\nname = "x"\n[[skillsets]]\nmodel = "{long}"\n')
    assert error(load_system, toml) == f"{path[:200]}… ({len(path)} characters): error: cannot read file: File name too long"
    toml = write(tmp_path, "s.toml", f'[system]\nname = "x"\n[[skillsets]]\nmodel = "s.rl"\nname = "{long}"\n')
    assert error(load_system, toml) == f"{toml}: error: skillsets entry 1 names '{'a' * 200}… (5000 characters)' but s.rl declares 's'"
    system, _ = load_system(SYSTEM)
    assert error(load_goals, path, system) == f"{path[:200]}… ({len(path)} characters): error: cannot read file: File name too long"
