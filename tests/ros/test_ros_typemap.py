"""Type-map parsing and its error messages."""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.errors import SourceError
from skinet.ros.typemap import parse_typemap

CORPUS = Path(__file__).resolve().parents[2].parent / "shared" / "corpus"


def test_corpus_typemap() -> None:
    text = (CORPUS / "isae_robot" / "isae_robot.json").read_text()
    assert parse_typemap(text, "isae_robot.json") == {
        "Pose": "geometry_msgs/Pose2D",
        "Float": "std_msgs/Float64",
        "Color": "std_msgs/String",
        "PointDetect": "geometry_msgs/Point",
    }


def test_idl_entries_and_extra_keys() -> None:
    text = '{"folder": "./", "type": [{"name": "Float", "idl": "float64"}, {"name": "S", "idl": "string<=8"}]}'
    assert parse_typemap(text, "t.json") == {"Float": "float64", "S": "string<=8"}


def test_empty_list() -> None:
    assert parse_typemap('{"type": []}') == {}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"type": [', "t.json:1:11: error: malformed JSON: Expecting value"),
        ('{\n  "type": [}\n', "t.json:2:12: error: malformed JSON: Expecting value"),
        ("[]", 't.json: error: a type map must be a JSON object with a "type" list'),
        ('{"types": []}', 't.json: error: missing key "type"'),
        ('{"type": {}}', 't.json: error: "type" must be a list'),
        ('{"type": ["Float"]}', "t.json: error: type entry 1 must be an object"),
        (
            '{"type": [{"name": "A", "idl": "bool"}, {"package": "std_msgs", "message": "Bool"}]}',
            't.json: error: type entry 2: missing key "name"',
        ),
        (
            '{"type": [{"name": "Float", "package": "std_msgs"}]}',
            't.json: error: type entry 1 ("Float"): missing key "message"',
        ),
        (
            '{"type": [{"name": "Float", "message": "Float64"}]}',
            't.json: error: type entry 1 ("Float"): missing key "package"',
        ),
        (
            '{"type": [{"name": "Float", "package": "std_msgs", "message": 3}]}',
            't.json: error: type entry 1 ("Float"): "message" must be a string',
        ),
        (
            '{"type": [{"name": "Float", "package": "std msgs", "message": "Float64"}]}',
            't.json: error: type entry 1 ("Float"): "package" is not a valid name: "std msgs"',
        ),
        (
            '{"type": [{"name": "", "idl": "bool"}]}',
            't.json: error: type entry 1: "name" is not a valid name: ""',
        ),
        (
            '{"type": [{"name": "A", "idl": "bool"}, {"name": "A", "idl": "int8"}]}',
            't.json: error: type entry 2 ("A"): duplicate type name "A"',
        ),
    ],
)
def test_errors(text: str, message: str) -> None:
    with pytest.raises(SourceError) as info:
        parse_typemap(text, "t.json")
    assert str(info.value) == message
    assert len(info.value.diagnostics) == 1
