"""Strict files (issue 27, item 1): a misspelt key or table of a system or scenario file is an
error at its position with the close names, never ignored; a system without properties is
refused by the commands that supervise it unless ``--no-properties`` says it is meant."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import services.monitor.__main__ as monitor_main
from skinet.errors import Pos, SourceError
from skinet.mission.scenario import parse_scenario
from skinet_cli.main import main

ROOT = Path(__file__).resolve().parents[1]
SKILLSETS = ROOT / "skillsets"
HEAD = '[system]\nname = "x"\nproperties = "spot_arm.props"\n'
PAIR = '[[skillsets]]\nmodel = "spot.rl"\n[[skillsets]]\nmodel = "manipulator.rl"\n'


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    for name in ("spot.rl", "manipulator.rl", "spot_arm.props"):
        shutil.copy(SKILLSETS / name, tmp_path / name)
    return tmp_path


@pytest.mark.parametrize(("text", "message"), [
    ('[system]\nname = "x"\npropertis = "spot_arm.props"\n' + PAIR,
     "3:1: error: unknown key 'propertis' in [system] (candidates: properties)"),
    (HEAD + '[[skillsets]]\nmodel = "spot.rl"\nmanger = "/spot/m"\n',
     "6:1: error: unknown key 'manger' in [[skillsets]] entry 1 (candidates: manager)"),
    (HEAD + PAIR + '\n[predicton]\naf = "literal"\n',
     "9:1: error: unknown table '[predicton]' (candidates: [prediction])"),
    (HEAD + PAIR + '[[skilsets]]\nmodel = "spot.rl"\n',
     "8:1: error: unknown table '[[skilsets]]' (candidates: [[skillsets]])"),
    ('nme = "x"\n' + HEAD + PAIR,
     "1:1: error: unknown key 'nme' at the top level (keys belong in a table) (expected one of: [system], "
     "[[skillsets]], [prediction])"),
    (HEAD + PAIR + '"mangaer" = "/m"\n',
     "8:1: error: unknown key 'mangaer' in [[skillsets]] entry 2 (candidates: manager)"),
    (HEAD + '[[skillsets]]\nmodel = "spot.rl"\nmanager = 5\n',
     "6:1: error: [[skillsets]] entry 1 'manager' must be a string, not 5"),
    ('[system]\nname = "x"\nproperties = ["spot_arm.props"]\n' + PAIR,
     "3:1: error: [system] 'properties' must be a string, not ['spot_arm.props']"),
    ('[system]\nname = "x"\nproperties = "spot_arm.props"\nmemory_limit = "lots"\n' + PAIR,
     "4:1: error: [system] memory_limit: not a size: 'lots' (e.g. 1GiB, 512MiB, 2GB)"),
])
def test_a_misspelt_system_file_is_refused(folder: Path, text: str, message: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    path = folder / "s.toml"
    path.write_text(text)
    code = main(["unsafe", str(path), "--no-predict"])
    out, err = capsys.readouterr()
    assert (code, out, err) == (1, "", f"{path}:{message}\n")


def test_the_typo_no_longer_means_no_properties(folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The new user's case: `propertis =` used to give "properties: none", exit 0."""
    (folder / "s.toml").write_text('[system]\nname = "x"\npropertis = "spot_arm.props"\n' + PAIR)
    assert main(["unsafe", str(folder / "s.toml")]) == 1
    assert "properties: none" not in capsys.readouterr().out


@pytest.mark.parametrize(("text", "message"), [
    ("[scenario]\nname = 'x'\nsystem = 'y'\nspeed = 2\n",
     "4:1: error: unknown key 'speed' in [scenario] (expected one of: name, system, topics, pilot)"),
    ("[scenario]\nname = 'x'\nsystem = 'y'\n[[steps]]\nt = 1\nskillset = 'spot'\ntransiton = 'teleop.start'\n",
     "7:1: error: unknown key 'transiton' in step 1 (candidates: transition)"),
    ("[scenario]\nname = 'x'\nsystem = 'y'\n[[step]]\nt = 1\n",
     "4:1: error: unknown table '[[step]]' (candidates: [[steps]])"),
    ("[scenaro]\nname = 'x'\nsystem = 'y'\n", "1:1: error: unknown table '[scenaro]' (candidates: [scenario])"),
    ("[scenario]\nname = 'x'\nsystem = 'y'\n[[steps]]\nt = 'soon'\nskillset = 'spot'\ntransition = 'a'\n",
     "5:1: error: step 1: 't' must be a number of seconds, got 'soon'"),
    ("[scenario]\nname = 'x'\nsystem = 'y'\npilot = 3\n",
     "4:1: error: [scenario] 'pilot' must be the path of a goals file (relative to the scenario)"),
])
def test_a_misspelt_scenario_file_is_refused(text: str, message: str) -> None:
    with pytest.raises(SourceError) as info:
        parse_scenario(text, "m.toml")
    assert str(info.value) == f"m.toml:{message}"


def test_scenario_names_are_checked_at_their_position(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "m.toml"
    path.write_text(f"[scenario]\nname = 'x'\nsystem = '{SKILLSETS / 'spot_arm.toml'}'\n[[steps]]\nt = 1\n"
                    "skillset = 'spot'\ntransition = 'init_power.start'\n[[steps]]\nt = 2\n  skillset = 'spott'\n"
                    "transition = 'init_power.start'\n")
    assert main(["demo", "--core", "--no-predict", str(path)]) == 1
    assert capsys.readouterr().err == (f"{path}:10:3: error: step 2: unknown skillset 'spott' "
                                       "(skillsets of spot_arm: spot, manipulator)\n")


# -- a system without properties -------------------------------------------------------------

def _no_properties(folder: Path) -> tuple[Path, Path]:
    system = folder / "bare.toml"
    system.write_text('# no properties\n[system]\nname = "bare"\n' + PAIR)
    scenario = folder / "m.toml"
    scenario.write_text("[scenario]\nname = 'm'\nsystem = 'bare.toml'\n[[steps]]\nt = 1\nskillset = 'spot'\n"
                        "transition = 'init_power.start'\n")
    return system, scenario


def test_a_system_without_properties_is_refused(folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    system, scenario = _no_properties(folder)
    refused = (f"{system}:2:1: error: system 'bare' has no safety properties: its [system] table names no "
               'properties file (properties = "FILE.props"); nothing would ever be reported unsafe '
               "(--no-properties runs it anyway)\n")
    for argv in (["run", str(system), "--once"], ["demo", "--core", str(scenario)], ["demo", str(scenario)]):
        assert main(argv) == 1, argv
        assert capsys.readouterr() == ("", refused)
    assert monitor_main.main([str(system)]) == 1
    assert capsys.readouterr() == ("", refused)


def test_an_empty_properties_file_is_refused(folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (folder / "none.props").write_text("# nothing yet\n")
    system = folder / "s.toml"
    system.write_text('[system]\nname = "x"\nproperties = "none.props"\n' + PAIR)
    assert main(["run", str(system), "--once"]) == 1
    assert capsys.readouterr().err == (f"{system}:3:1: error: system 'x' has no safety properties: none.props "
                                       "defines none; nothing would ever be reported unsafe (--no-properties runs "
                                       "it anyway)\n")


def test_no_properties_on_purpose(folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, scenario = _no_properties(folder)
    assert main(["demo", "--core", "--no-properties", str(scenario)]) == 0
    assert "   violations: 0" in capsys.readouterr().out
    # Analysis commands take such a system as it is: they say so.
    assert main(["unsafe", str(folder / "bare.toml"), "--no-predict"]) == 0
    assert "properties: none" in capsys.readouterr().out


# -- locating keys -----------------------------------------------------------------------------

def test_locate_follows_tables_and_skips_strings() -> None:
    from skinet.files.toml import locate

    text = ('# c\n[system]\nname = "x"\nnote = """\n[fake]\nkey = 1\n"""\n[[skillsets]]\nmodel = "a"\n'
            "[[skillsets]]\n  'manager' = 'b'\n[prediction.properties.p]\naf = 'fair'\n")
    assert locate(text, ("system",), "name") == Pos(3, 1)
    assert locate(text, ("fake",)) is None and locate(text, ("fake",), "key") is None
    assert locate(text, ("skillsets", 1), "manager") == Pos(11, 3)
    assert locate(text, ("skillsets", 0), "manager") is None
    assert locate(text, ("prediction", "properties", "p"), "af") == Pos(13, 1)
    assert locate(text, ("skillsets", 1)) == Pos(10, 1)
