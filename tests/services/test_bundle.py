"""Incident bundles: ``skinet record --bundle`` during a run through the whole chain, then
``skinet replay BUNDLE --verify`` re-runs it to the same verdicts; altered and bad files are refused."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from skinet.wire import foxglove as fx
from tests.processes import run_skinet as skinet
from tests.services.conftest import REPO, LivelinessWatch, client_args, open_client
from tests.services.test_dashboard import VIOLATIONS, play


@contextlib.contextmanager
def recording(router: str, path: Path, system: str = "spot_arm") -> Iterator[None]:
    """``skinet record SYSTEM --bundle PATH`` on a client of ``router``, subscribed (its liveliness token seen)
    when the block starts, stopped with SIGTERM (and asserted to exit 0) when it ends."""
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "record", system, "--bundle", str(path),
                             *client_args(router)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        session = open_client(router)
        watch = LivelinessWatch(session, f"skinet/{system}/alive/recorder/*")
        try:
            watch.wait(lambda alive: bool(alive), timeout=30)
        finally:
            watch.close()
            session.close()
        yield
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err


def record(router: str, run: str | Path, path: Path, system: str = "spot_arm") -> list:
    with recording(router, path, system):
        return play(run, router) if isinstance(run, (str, Path)) else run(router)


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
        divergences = [json.loads(m.data) for _, c, m in reader.iter_messages(topics=[fx.DIVERGENCES])]
        lines = [json.loads(m.data)["message"] for _, c, m in reader.iter_messages(topics=[fx.LOG])]
        series = [json.loads(m.data) for _, c, m in reader.iter_messages(topics=[fx.SERIES])]
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert {s.topic for s in fx.channels()} - topics <= {fx.PILOT, fx.DIVERGENCES}  # none in this run
    assert [(v["property"], v["seq"]) for v in violations] == [(p, i) for p, i, _ in VIOLATIONS]
    # The monitor lists the onsets beside its divergences (for views that join later): violations, not divergences.
    assert divergences == [] and not [line for line in lines if "divergence" in line]
    assert series[-1]["divergences"] == 0 and series[-1]["violations"] == 3
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


MID_RUN = 20  # the step of the unassisted run after which the recorder starts: before its three violations


def test_a_bundle_taken_mid_run_verifies_from_its_first_recorded_state(router, tmp_path: Path) -> None:
    """The recorder starts while the paper's unassisted run is at step 20: the bundle starts there, and its
    re-run from that state makes the same verdicts and unsafe reports, the three violations included."""
    from mcap.reader import make_reader

    path = tmp_path / "mid-run.mcap"
    started = contextlib.ExitStack()

    def after(r) -> None:
        if r.index == MID_RUN:  # the mission waits here until the recorder is subscribed
            started.enter_context(recording(router, path))

    with started:
        records = play("unassisted", router, after)
    assert [(p, r.index) for r in records for p in r.violations] == [(p, i) for p, i, _ in VIOLATIONS]
    with path.open("rb") as f:
        reader = make_reader(f)
        states = [json.loads(m.data)["seq"] for _, _, m in reader.iter_messages(topics=["skinet/spot_arm/state"],
                                                                               log_time_order=True)]
    with path.open("rb") as f:
        violations = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=[fx.VIOLATIONS])]
    assert MID_RUN <= states[0] <= MID_RUN + 1 and states[-1] == records[-1].index
    assert [(v["property"], v["seq"]) for v in violations] == [(p, i) for p, i, _ in VIOLATIONS]
    done = skinet("replay", str(path), "--verify")
    assert (done.returncode, done.stdout) == (0, "0 differences\n"), done.stderr
    steps = int(done.stderr.split(", ")[1].split()[0])
    assert steps == records[-1].index - states[0]  # every step after the first recorded state


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
        play("unassisted", router, tap=incidents.record)
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
    assert all("model divergence" not in t for t in triggers)  # the onsets the monitor lists are not divergences


# -- the incidents folder: its cap, no partial bundle, the monitor's process -----------------------


BUNDLE_NAME = r"spot_arm-\d{8}-\d{6}-\d{3}\.mcap"


def _divergence(n: int) -> bytes:
    """Monitor m1's divergence list with its entry ``n`` new: an incident."""
    from skinet.wire.codec import encode
    from skinet.wire.messages import Divergence, Divergences

    entry = Divergence(n=n, kind="divergence", seq=n, stamp=time.time(), skillset="spot",
                       event=f"spot:init_power.success.powered_on#{n}", reason="init_power is not running")
    return encode(Divergences(system="spot_arm", monitor="m1", stamp=time.time(), older=n, entries=[entry]))


class Divergent:
    """Hands ``incidents`` divergence lists as a monitor would, each one more incident."""

    def __init__(self, incidents) -> None:
        self.incidents, self.n = incidents, 0

    def incident(self) -> None:
        """One incident, and its bundle written or failed."""
        from skinet.wire import keys
        from tests.services.test_monitor import wait_until

        done = len(self.incidents.written) + self.incidents.failed
        self.incidents.record(keys.divergences("spot_arm"), _divergence(self.n), time.time())
        self.n += 1
        wait_until(lambda: len(self.incidents.written) + self.incidents.failed == done + 1, 20,
                   f"incident {self.n}'s bundle")


def test_the_incidents_folder_keeps_the_newest_bundles_and_never_a_partial_one(client_factory, tmp_path) -> None:
    from services.monitor.incidents import Incidents
    from skinet.system.load import load_system
    from skinet.wire.convert import bundle
    from tests.services.test_dashboard import SYSTEM_FILE

    model = bundle(load_system(SYSTEM_FILE)[0])
    folder = tmp_path / "incidents"
    folder.mkdir()
    old = [folder / f"spot_arm-20240101-00000{i}-000.mcap" for i in range(3)]
    for i, p in enumerate(old):
        p.write_bytes(b"x" * 100)
        os.utime(p, (1_700_000_000 + i, 1_700_000_000 + i))
    others = [folder / "notes.txt", folder / "nav2-20240101-000000-000.mcap", folder / "spot_arm-copy.mcap"]
    for p in others:
        p.write_text("not ours")
    (folder / ".spot_arm-20240101-000003-000.mcap.partial").write_bytes(b"a killed writer's")

    incidents = Incidents(client_factory(), model, folder, window=0.05, max_files=2)
    try:
        # At start: the killed writer's partial bundle goes, and the oldest bundle (three are over the cap).
        assert incidents.removed == old[:1]
        assert sorted(p.name for p in folder.iterdir()) == sorted(p.name for p in [*old[1:], *others])
        divergent = Divergent(incidents)
        divergent.incident()
        assert incidents.removed == old[:2]  # oldest first
        divergent.incident()
        assert incidents.removed == old and incidents.failed == 0
    finally:
        incidents.close()
    ours = sorted(p for p in folder.iterdir() if re.fullmatch(BUNDLE_NAME, p.name))
    assert ours == sorted(incidents.written) and len(ours) == 2
    assert sorted(p for p in folder.iterdir() if p not in ours) == sorted(others)
    first = incidents.written

    # By size: every bundle is over one byte; the newest stays all the same, alone.
    incidents = Incidents(client_factory(), model, folder, window=0.05, max_bytes=1)
    try:
        assert incidents.removed == first[:1]
        divergent = Divergent(incidents)
        divergent.n = 2
        divergent.incident()
        assert incidents.removed == first
    finally:
        incidents.close()
    assert [p for p in folder.iterdir() if re.fullmatch(BUNDLE_NAME, p.name)] == incidents.written
    done = skinet("replay", str(incidents.written[0]), "--verify")
    assert done.returncode == 0, done.stderr


def test_a_bundle_that_cannot_be_finished_leaves_no_file(client_factory, tmp_path, monkeypatch) -> None:
    import services.monitor.incidents as incidents_module
    from services.foxglove.bundle import BundleSink
    from skinet.system.load import load_system
    from skinet.wire.convert import bundle
    from tests.services.test_dashboard import SYSTEM_FILE

    class FullDisk(BundleSink):
        def close(self) -> None:
            super().close()
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(incidents_module, "BundleSink", FullDisk)
    folder = tmp_path / "incidents"
    incidents = incidents_module.Incidents(client_factory(), bundle(load_system(SYSTEM_FILE)[0]), folder, window=0.05)
    try:
        Divergent(incidents).incident()
    finally:
        incidents.close()
    assert (incidents.failed, incidents.written, list(folder.iterdir())) == (1, [], [])


def test_a_failing_property_is_found_in_a_verdicts_payload_by_its_bytes() -> None:
    """The ring reads a Verdicts payload in full only when it holds msgpack's bytes of a failing property."""
    from services.monitor.incidents import HOLDS_FALSE
    from skinet.wire.codec import encode
    from skinet.wire.messages import PropertyVerdict, Verdicts

    def verdicts(*holds: bool) -> bytes:
        return encode(Verdicts(system="spot_arm", seq=7, stamp=1.0, properties=[
            PropertyVerdict(name=f"p{i}", holds=h) for i, h in enumerate(holds)]))

    assert [HOLDS_FALSE in verdicts(*h) for h in [(True, True), (True, False), (False, True), ()]] == \
        [False, True, True, False]


def test_a_failed_pilot_is_an_incident_once_per_goal(client_factory, tmp_path) -> None:
    """A pilot's statuses come from the session, not the monitor's tap: its failure of a goal triggers one bundle
    holding its statuses; the same failure said again does not trigger another, the next goal's does."""
    from mcap.reader import make_reader

    from services.monitor.incidents import Incidents
    from skinet.system.load import load_system
    from skinet.wire import keys
    from skinet.wire.codec import encode
    from skinet.wire.convert import bundle
    from skinet.wire.messages import PilotStatus
    from tests.services.test_dashboard import SYSTEM_FILE
    from tests.services.test_monitor import wait_until

    folder = tmp_path / "incidents"
    incidents = Incidents(client_factory(), bundle(load_system(SYSTEM_FILE)[0]), folder, window=0.05)
    publisher = client_factory().declare_publisher(keys.pilot_status("spot_arm"))
    try:
        wait_until(lambda: publisher.matching_status.matching, 10, "the incidents' subscriber of pilot statuses")
        seq = 0

        def status(state: str, goal: int, reason: str = "") -> None:
            nonlocal seq
            seq += 1
            publisher.put(encode(PilotStatus(system="spot_arm", pilot="p1", seq=seq, stamp=time.time(),
                                             state=state, goal_id=goal, reason=reason)))

        status("driving", 1)
        status("failed", 1, "spot:init_power failed 3 times")
        wait_until(lambda: len(incidents.written) == 1, 20, "the failed goal's bundle")
        status("failed", 1, "spot:init_power failed 3 times")  # said again: the same incident
        status("failed", 2, "no plan")
        wait_until(lambda: len(incidents.written) == 2, 20, "the second goal's bundle")
    finally:
        publisher.undeclare()
        incidents.close()
    assert incidents.failed == 0 and len(incidents.written) == 2
    triggers, states = [], []
    for path in incidents.written:
        with path.open("rb") as f:
            reader = make_reader(f)
            triggers.append({m.name: m.metadata for m in reader.iter_metadata()}["skinet"]["trigger"])
            states.append([json.loads(m.data)["state"] for _, _, m in reader.iter_messages(topics=[fx.PILOT])])
    assert triggers == ["pilot failed goal 1: spot:init_power failed 3 times", "pilot failed goal 2: no plan"]
    assert states[0][:2] == ["driving", "failed"]


def test_the_monitor_process_writes_an_incident_bundle_that_verifies(router, spawn, client_factory, tmp_path) -> None:
    """``python -m services.monitor SYSTEM --incidents DIR`` on a router; a bridge reports an outcome of a skill
    never started (a model divergence), then ten good events: a bundle appears in DIR, complete, and verifies."""
    from mcap.reader import make_reader

    from tests.services.conftest import LivelinessWatch
    from tests.services.test_divergences import TEN
    from tests.services.test_monitor import Events, wait_until

    folder = tmp_path / "incidents"
    session = client_factory()
    watch = LivelinessWatch(session, "skinet/spot_arm/alive/monitor/m1")
    proc = spawn("services.monitor", str(REPO / "skillsets" / "spot_arm.toml"), "--id", "m1", "--incidents",
                 str(folder), "--incident-window", "1", *client_args(router))
    try:
        watch.wait(lambda alive: bool(alive), timeout=60)
    finally:
        watch.close()
    events = Events(client_factory())
    events.send("spot", "init_power.success.powered_on")  # init_power never started
    for skillset, transition in TEN:
        events.send(skillset, transition)
    wait_until(lambda: folder.is_dir() and any(re.fullmatch(BUNDLE_NAME, p.name) for p in folder.iterdir()), 30,
               "an incident bundle")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(30) == 0
    [path] = list(folder.iterdir())  # renamed once complete: no partial file ever shows under its name
    assert re.fullmatch(BUNDLE_NAME, path.name)
    with path.open("rb") as f:
        reader = make_reader(f)
        trigger = {m.name: m.metadata for m in reader.iter_metadata()}["skinet"]["trigger"]
        shown = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=[fx.DIVERGENCES])]
    assert trigger == "model divergence"
    assert [(d["seq"], d["event"]) for d in shown] == [(1, "spot:init_power.success.powered_on#1")]
    done = skinet("replay", str(path), "--verify")
    assert (done.returncode, done.stdout) == (0, "0 differences\n"), done.stderr
