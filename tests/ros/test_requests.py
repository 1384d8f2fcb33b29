"""Requests to a skillset manager as an operator GUI sends them (skinet/ros/requests.py): the CDR the
simulated manager decodes, and the running ids read back from a manager's status."""

from __future__ import annotations

import doctest
from pathlib import Path

import pytest

import skinet.ros.requests
from skinet.system.load import load_system, load_typemap
from skinet.ros.requests import Writer, event_request, skill_ids, skill_interrupt, skill_request, status_request
from skinet.ros.typestore import build_typestore, decode, encode, to_plain
from services.simulator.manager import Manager

ROOT = Path(__file__).resolve().parents[2]
SYSTEM = ROOT / "skillsets" / "spot_arm.toml"


def test_docstring_examples(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    assert doctest.testmod(skinet.ros.requests).failed == 0


def test_requests_decode_as_the_manager_reads_them_and_ids_come_back_from_its_status() -> None:
    system, _ = load_system(SYSTEM)
    spot = system.component("spot").skillset
    store = build_typestore(spot, load_typemap(SYSTEM))
    topic, payload = skill_request(store, spot, "go_to_waypoint", "p-7", {"target": {"x": 1.5, "z": -2.0}})
    assert (topic.kind, topic.skill) == ("skill_request", "go_to_waypoint")
    msg = to_plain(decode(store, topic.typename, payload))
    assert msg == {"id": "p-7", "input": {"target": {"x": 1.5, "y": 0.0, "z": -2.0}}}
    topic, payload = skill_interrupt(store, spot, "teleop", "gui-3")
    assert (topic.topic, to_plain(decode(store, topic.typename, payload))) == (
        "spot_skillset/skill/teleop/interrupt", {"id": "gui-3"})
    topic, payload = event_request(store, spot, "e-1", "power_switchoff")
    assert to_plain(decode(store, topic.typename, payload)) == {"id": "e-1", "name": "power_switchoff"}
    assert status_request(store, spot)[0].topic == "spot_skillset/status_request"
    manager = Manager(spot, store)
    manager.skill_request("init_power", "p-8")
    status = manager.status()
    ids = skill_ids(store, spot, encode(store, status.typename, status.msg))
    assert (ids["init_power"].state, ids["init_power"].id, ids["teleop"].state) == (1, "p-8", 0)
    with pytest.raises(ValueError, match=r"^not a SkillsetStatus of manipulator: "):
        skill_ids(build_typestore(system.component("manipulator").skillset, load_typemap(SYSTEM)),
                  system.component("manipulator").skillset, encode(store, status.typename, status.msg))


def test_a_writer_numbers_its_attachments() -> None:
    w = Writer(b"g" * 16)
    assert [w.attachment(5)[:8] for _ in range(2)] == [(1).to_bytes(8, "little"), (2).to_bytes(8, "little")]
    with pytest.raises(ValueError, match="a GID has 16 bytes, got 3"):
        Writer(b"abc")
