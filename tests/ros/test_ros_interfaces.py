"""Message generation compared byte for byte with ONERA's output (corpus/isae_robot/msg)."""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.errors import Pos, SourceError
from skinet.lang.model import Progress, Skill, Skillset, Variable
from skinet.lang.parser import parse_skillset
from skinet.ros.interfaces import (
    camel_case,
    data_topic,
    data_type,
    event_request_topic,
    event_response_topic,
    generate_messages,
    package_name,
    skill_topic,
    skill_type,
    snake_case,
    status_field,
    status_request_topic,
    status_topic,
)
from skinet.ros.typemap import parse_typemap
from tests.corpus import require_corpus

CORPUS = Path(__file__).resolve().parents[2].parent / "shared" / "corpus"
ISAE = CORPUS / "isae_robot"


def isae() -> tuple[Skillset, dict[str, str]]:
    require_corpus()
    rl = ISAE / "isae_robot.rl"
    skillset = parse_skillset(rl.read_text(), str(rl))
    typemap = parse_typemap((ISAE / "isae_robot.json").read_text(), "isae_robot.json")
    return skillset, typemap


def test_generated_file_set_equals_corpus() -> None:
    msgs = generate_messages(*isae())
    assert sorted(msgs) == sorted(p.stem for p in (ISAE / "msg").glob("*.msg"))


@pytest.mark.parametrize("path", sorted((ISAE / "msg").glob("*.msg")) or [  # collected without the corpus
    pytest.param(ISAE / "msg" / "absent.msg", marks=pytest.mark.corpus)], ids=lambda p: p.stem)
def test_generated_file_is_byte_identical(path: Path) -> None:
    msgs = generate_messages(*isae())
    assert msgs[path.stem].encode() == path.read_bytes()


def test_package_name() -> None:
    skillset, _ = isae()
    assert package_name(skillset) == "isae_robot_skillset_interfaces"
    assert package_name("turtlebot") == "turtlebot_skillset_interfaces"


@pytest.mark.parametrize(
    ("name", "snake", "camel"),
    [
        ("move_to", "move_to", "MoveTo"),
        ("GoTo", "go_to", "GoTo"),
        ("getHome", "get_home", "GetHome"),
        ("currentpose", "currentpose", "Currentpose"),
        ("arm_moving_to_HP", "arm_moving_to_hp", "ArmMovingToHp"),
        ("init_power", "init_power", "InitPower"),
    ],
)
def test_name_conversions(name: str, snake: str, camel: str) -> None:
    assert snake_case(name) == snake
    assert camel_case(name) == camel


def test_type_and_field_names() -> None:
    assert skill_type("GoTo", "Request") == "SkillGoToRequest"
    assert skill_type("move_to") == "SkillMoveTo"
    assert data_type("pose", "Response") == "DataPoseResponse"
    assert status_field("getHome") == "skill_get_home"


def test_topics() -> None:
    skillset, _ = isae()
    assert status_topic(skillset) == "isae_robot_skillset/status"
    assert status_request_topic(skillset) == "isae_robot_skillset/status_request"
    assert event_request_topic(skillset) == "isae_robot_skillset/event_request"
    assert event_response_topic(skillset) == "isae_robot_skillset/event_response"
    assert skill_topic(skillset, "move_to", "request") == "isae_robot_skillset/skill/move_to/request"
    assert skill_topic("turtlebot", "GoTo", "progress") == "turtlebot_skillset/skill/go_to/progress"
    for kind in ("response", "interrupt"):
        assert skill_topic(skillset, skillset.skill("move_to"), kind).endswith(f"/move_to/{kind}")
    assert data_topic(skillset, "pose") == "isae_robot_skillset/data/pose"
    assert data_topic(skillset, skillset.data[0], "request") == "isae_robot_skillset/data/pose/request"
    assert data_topic(skillset, "pose", "response") == "isae_robot_skillset/data/pose/response"
    with pytest.raises(ValueError):
        skill_topic(skillset, "move_to", "result")
    with pytest.raises(ValueError):
        data_topic(skillset, "pose", "progress")


def test_skill_without_input_output_progress_fields() -> None:
    """Rules beyond the corpus: empty Input, no Output, Progress from the block alone."""
    skillset = Skillset(
        name="tiny",
        source="dir/tiny.rl",
        skills=(
            Skill("GoHome", progress=Progress(1.0, ()), pos=Pos(3, 11)),
            Skill("idle"),
        ),
    )
    msgs = generate_messages(skillset, {})
    assert msgs["SkillGoHomeInput"] == "# Generated from tiny.rl:3:10\n\n"
    assert msgs["SkillGoHomeProgress"] == "# Generated from tiny.rl:3:10\nstring id\n\n"
    assert msgs["SkillGoHomeRequest"] == "# Generated from tiny.rl:3:10\nstring id\nSkillGoHomeInput input\n"
    assert msgs["SkillIdleInput"] == "# Generated from tiny.rl\n\n"
    assert "SkillGoHomeOutput" not in msgs and "SkillIdleProgress" not in msgs
    assert msgs["SkillsetStatus"].splitlines()[2:4] == [
        "SkillGoHomeStatus skill_go_home",
        "SkillIdleStatus skill_idle",
    ]
    assert msgs["DataRequest"] == "\nstring id\n"


def test_missing_type_names_type_and_every_use() -> None:
    skillset, typemap = isae()
    del typemap["Pose"]
    with pytest.raises(SourceError) as info:
        generate_messages(skillset, typemap)
    rl = str(ISAE / "isae_robot.rl")
    assert str(info.value).splitlines() == [
        f'{rl}:11:16: error: type "Pose" is not in the type map (data "pose")',
        f'{rl}:58:21: error: type "Pose" is not in the type map (input "target" of skill "move_to")',
        f'{rl}:124:31: error: type "Pose" is not in the type map '
        '(progress field "detection" of skill "track_target")',
    ]


def test_missing_type_without_type_position_uses_field_position() -> None:
    skillset = Skillset(
        name="s", source="s.rl", skills=(Skill("k", outputs=(Variable("o", "T", Pos(4, 9)),)),)
    )
    with pytest.raises(SourceError, match=r'^s\.rl:4:9: error: type "T" is not in the type map '
                       r'\(output "o" of skill "k"\)$'):
        generate_messages(skillset, {})
