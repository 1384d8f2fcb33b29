"""The ``[prediction]`` table of a system file (docs/semantics.md §5, §6.2, §6.3): options and their errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.errors import SourceError
from skinet.system.load import load_system
from skinet.system.prediction import PredictionOptions, PropertyOptions
from skinet.verify.algorithm1 import analyse
from skinet.system.load import load_state

SKILLSETS = Path(__file__).resolve().parents[1] / "skillsets"
HEAD = f'''[system]
name = "mobile_manip"
properties = "{SKILLSETS / 'mobile_manip.props'}"

[[skillsets]]
model = "{SKILLSETS / 'mobile_base.rl'}"

[[skillsets]]
model = "{SKILLSETS / 'mobile_arm.rl'}"

'''


def system_file(tmp_path: Path, table: str) -> Path:
    path = tmp_path / "system.toml"
    path.write_text(HEAD + table)
    return path


def test_defaults_and_per_property_options(tmp_path: Path) -> None:
    system, _ = load_system(system_file(tmp_path, '[prediction]\naf = "literal"\n\n'
                                        '[prediction.properties.still_grasp]\naf = "fair"\nforced = false\n'))
    assert system.prediction == PredictionOptions(
        PropertyOptions(af="literal"), {"still_grasp": PropertyOptions(af="fair", forced=False)})
    assert load_system(SKILLSETS / "spot_arm.toml")[0].prediction == PredictionOptions()


@pytest.mark.parametrize(("table", "message"), [
    ('[prediction]\nfair = true\n', ":12:1: error: [prediction] unknown option 'fair' "
                                    "(options: af, events_uncontrollable, forced)"),
    ('[prediction]\naf = "fairish"\n', ':12:1: error: [prediction] af must be "fair" or "literal", not \'fairish\''),
    ('[prediction]\nforced = "yes"\n', ":12:1: error: [prediction] forced must be true or false, not 'yes'"),
    ('[prediction.properties.speed_guard]\naf = "literal"\n',
     ":11:24: error: [prediction.properties] unknown property 'speed_guard' (properties: stowed_drive, still_grasp)"),
    ('[prediction.properties.still_grasp]\nevents = true\n',
     ":12:1: error: [prediction.properties.still_grasp] unknown option 'events' "
     "(options: af, events_uncontrollable, forced)"),
    ('[[prediction]]\naf = "fair"\n', ":11:3: error: [prediction] must be a table"),
])
def test_bad_options_are_located(tmp_path: Path, table: str, message: str) -> None:
    path = system_file(tmp_path, table)
    with pytest.raises(SourceError) as err:
        load_system(path)
    assert str(err.value) == f"{path}{message}"


def test_forced_option_per_property(tmp_path: Path) -> None:
    system, _ = load_system(system_file(tmp_path, '[prediction.properties.stowed_drive]\nforced = false\n'))
    marking = load_state(SKILLSETS / "states" / "unfolding.json", system)
    assert analyse(system, marking).unsafe == []
    default, _ = load_system(SKILLSETS / "mobile_manip.toml")
    assert [(u.transition, u.constraint) for u in analyse(default, marking).unsafe] == [
        ("navigate.start", "forced"), ("dock_station.start", "forced")]
