"""Incident bundles: ``skinet record --bundle`` during a run through the whole chain, then
``skinet replay BUNDLE --verify`` re-runs it to the same verdicts; altered and bad files are refused."""

from __future__ import annotations

import hashlib
import io
import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from skinet.wire import foxglove as fx
from tests.services.conftest import REPO, LivelinessWatch, client_args, open_client
from tests.services.test_dashboard import VIOLATIONS, play


def skinet(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skinet_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=300)


def record(router: str, run: str | Path, path: Path, system: str = "spot_arm") -> list:
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "record", system, "--bundle", str(path),
                             *client_args(router)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    session = open_client(router)
    watch = LivelinessWatch(session, f"skinet/{system}/alive/recorder/*")
    try:
        watch.wait(lambda alive: bool(alive), timeout=30)
        records = play(run, router) if isinstance(run, (str, Path)) else run(router)
    finally:
        watch.close()
        session.close()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    return records


@pytest.fixture(scope="module")
def unassisted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tests.services.conftest import free_port, open_router

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_router(endpoint)
    try:
        path = tmp_path_factory.mktemp("bundle") / "unassisted.mcap"
        records = record(endpoint, "unassisted", path)
        assert [(p, r.index) for r in records for p in r.violations] == [(p, i) for p, i, _ in VIOLATIONS]
        return path
    finally:
        router.close()


def test_the_unassisted_runs_bundle_verifies_with_zero_differences(unassisted: Path) -> None:
    done = skinet("replay", str(unassisted), "--verify")
    assert (done.returncode, done.stdout) == (0, "0 differences\n"), done.stderr
    steps = int(done.stderr.split(", ")[1].split()[0])
    assert steps >= VIOLATIONS[-1][1]


def test_the_bundle_opens_on_the_foxglove_channels_with_the_model_attached(unassisted: Path) -> None:
    from mcap.reader import make_reader

    with unassisted.open("rb") as f:
        reader = make_reader(f)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        violations = [json.loads(m.data) for _, c, m in reader.iter_messages(topics=[fx.VIOLATIONS])]
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert {s.topic for s in fx.channels()} - topics <= {fx.PILOT, fx.DIVERGENCES}  # none in this run
    assert [(v["property"], v["seq"]) for v in violations] == [(p, i) for p, i, _ in VIOLATIONS]
    assert sorted(attachments) == ["model.json", "properties/spot_arm.props", "skillsets/manipulator.rl",
                                   "skillsets/spot.rl"]
    assert meta["skinet.attachments"] == {n: "sha256:" + hashlib.sha256(d).hexdigest() for n, d in attachments.items()}
    assert meta["skinet"]["system"] == "spot_arm"


def _rewrite(src: Path, dst: Path, message=None, attachment=None) -> None:
    """Copy a bundle, changing one recorded message's JSON (``message(topic, body) -> body | None``) or
    one attachment's bytes (``attachment(name, data) -> data``), digests kept as recorded."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with src.open("rb") as f, dst.open("wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out)
        w.start(profile="", library="test")
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channels = {cid: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id])
                    for cid, c in summary.channels.items()}
        for _, c, m in reader.iter_messages(log_time_order=True):
            data = m.data
            if message is not None:
                body = message(c.topic, json.loads(data))
                data = data if body is None else json.dumps(body).encode()
            w.add_message(channels[c.id], log_time=m.log_time, publish_time=m.publish_time, sequence=m.sequence,
                          data=data)
        for a in reader.iter_attachments():
            data = a.data if attachment is None else attachment(a.name, a.data)
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, data)
        for md in reader.iter_metadata():
            w.add_metadata(md.name, dict(md.metadata))
        w.finish()


def test_one_altered_verdict_is_reported_at_its_step(unassisted: Path, tmp_path: Path) -> None:
    prop, step, _ = VIOLATIONS[1]
    done_once = []

    def flip(topic: str, body: dict):
        if topic == "skinet/spot_arm/verdicts" and body["seq"] == step and not done_once:
            done_once.append(True)
            for p in body["properties"]:
                if p["name"] == prop:
                    p["holds"] = True
            return body
        return None

    altered = tmp_path / "altered.mcap"
    _rewrite(unassisted, altered, message=flip)
    assert done_once
    done = skinet("replay", str(altered), "--verify")
    assert done.returncode == 3, done.stderr
    assert done.stdout == f"step {step}: verdict of {prop}: recorded holds, re-run VIOLATED\n1 difference\n"


def test_an_altered_attachment_is_refused_with_its_digest(unassisted: Path, tmp_path: Path) -> None:
    altered = tmp_path / "altered.mcap"
    _rewrite(unassisted, altered, attachment=lambda name, data: data + b"\n" if name == "model.json" else data)
    done = skinet("replay", str(altered), "--verify")
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.startswith(f"skinet: error: {altered}: attachment model.json was altered: recorded digest "
                                  "sha256:")
    assert len(done.stderr.splitlines()) == 1


@pytest.mark.parametrize("damage", ["truncated", "not mcap", "no file"])
def test_bad_bundles_are_one_line_errors(unassisted: Path, tmp_path: Path, damage: str) -> None:
    bad = tmp_path / "bad.mcap"
    data = unassisted.read_bytes()
    if damage == "truncated":
        bad.write_bytes(data[: len(data) // 2])
    elif damage == "not mcap":
        bad.write_text("{\"not\": \"mcap\"}\n")
    done = skinet("replay", str(bad), "--verify")
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert len(done.stderr.splitlines()) == 1, done.stderr
    expected = {"truncated": f"skinet: error: {bad}: truncated",
                "not mcap": f"skinet: error: {bad}: not an MCAP file",
                "no file": f"skinet: error: {bad}: cannot read file: No such file or directory"}[damage]
    assert done.stderr.startswith(expected), done.stderr


@pytest.mark.parametrize("scenario, system, divergences", [
    ("skillsets/missions/assisted.toml", "spot_arm", 0),
    ("examples/nav2/missions/nav2_run.toml", "nav2", 0),
], ids=["assisted", "nav2"])
def test_bundles_of_other_runs_verify(router, tmp_path: Path, scenario: str, system: str, divergences: int) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "run.mcap"
    record(router, REPO / scenario, path, system)
    done = skinet("replay", str(path), "--verify")
    assert (done.returncode, done.stdout) == (0, "0 differences\n"), done.stderr
    with path.open("rb") as f:
        shown = [m for _, _, m in make_reader(f).iter_messages(topics=[fx.DIVERGENCES])]
    assert len(shown) == divergences


def test_a_bundle_with_an_injected_fault_verifies_and_shows_the_divergence(router, client_factory, tmp_path) -> None:
    """A faulty bridge reports an outcome of a skill never started (a model divergence), then ten good events."""
    from mcap.reader import make_reader

    from services.monitor import start_monitor
    from skinet.system.load import load_system
    from tests.services.test_divergences import TEN
    from tests.services.test_monitor import SYSTEM_FILE, Events, wait_until

    path = tmp_path / "fault.mcap"
    system, _ = load_system(SYSTEM_FILE)

    monitors = []

    def faulty(_router: str) -> list:
        monitor = start_monitor(client_factory(), system)
        monitors.append(monitor)  # kept until the recorder stopped: it fetches the model from it
        events = Events(client_factory())
        events.send("spot", "init_power.success.powered_on")  # init_power never started
        for skillset, transition in TEN:
            events.send(skillset, transition)
        wait_until(lambda: monitor.snapshot().state.seq == 11 and monitor.divergences_published == 1, 10,
                   "eleven steps and the divergence")
        return []

    try:
        record(router, faulty, path)  # type: ignore[arg-type]
    finally:
        for m in monitors:
            m.close()
    done = skinet("replay", str(path), "--verify")
    assert (done.returncode, done.stdout) == (0, "0 differences\n"), done.stderr
    with path.open("rb") as f:
        shown = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=[fx.DIVERGENCES])]
    assert [(d["seq"], d["event"]) for d in shown] == [(1, "spot:init_power.success.powered_on#1")]


def test_incidents_are_written_around_the_violations_and_verify(router, client_factory, tmp_path) -> None:
    from mcap.reader import make_reader

    from services.monitor.incidents import Incidents
    from skinet.system.load import load_system
    from skinet.wire.convert import bundle
    from tests.services.test_dashboard import SYSTEM_FILE

    system, _ = load_system(SYSTEM_FILE)
    folder = tmp_path / "incidents"
    incidents = Incidents(client_factory(), bundle(system), folder, window=1.0)
    try:
        play("unassisted", router)
    finally:
        incidents.close()
    assert incidents.failed == 0 and incidents.written and sorted(folder.iterdir()) == sorted(incidents.written)
    triggers = []
    for path in incidents.written:
        with path.open("rb") as f:
            triggers.append({m.name: m.metadata for m in make_reader(f).iter_metadata()}["skinet"]["trigger"])
        done = skinet("replay", str(path), "--verify")
        assert (done.returncode, done.stdout) == (0, "0 differences\n"), done.stderr
    said = "; ".join(triggers)
    assert [f"violation of {p} at step {i}" in said for p, i, _ in VIOLATIONS] == [True] * 3
    assert triggers[0].startswith(f"violation of {VIOLATIONS[0][0]} at step {VIOLATIONS[0][1]}")
