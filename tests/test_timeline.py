"""Monitor logs, ``skinet record``, ``skinet demo --log/--timeline`` and ``skinet timeline``."""

from __future__ import annotations

import functools
import json
import struct
import threading
import time
from pathlib import Path

import pytest
import zenoh

from services.common.zenoh_config import session_config
from skinet_cli.main import main
from skinet.errors import SourceError
from skinet.system.load import load_system
from skinet.files.read import read_text
from skinet.mission.scenario import parse_scenario, replay
from skinet_cli.timeline import load_log
from skinet.mission.log import records_to_log
from skinet.plot.timeline import draw, flagged, lanes_of, violations
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.convert import bundle
from skinet.wire.log import MAX_ERRORS, Entry, log_line, read_log
from skinet.wire.messages import (
    CanonicalEvent, LiveState, PropertyVerdict, SkillsetStatus, StateSpaceReport, UnsafeEntry, UnsafeReport, Verdicts,
)
from tests.loopback import free_endpoint

REPO = Path(__file__).resolve().parents[1]
MISSIONS = REPO / "skillsets" / "missions"
SYSTEM = "spot_arm"


def _messages() -> list[tuple[str, object]]:
    status = {"spot": SkillsetStatus(resources={"control_mode": "Busy"}, running=["teleop"])}
    return [
        (keys.events(SYSTEM, "spot"), CanonicalEvent(system=SYSTEM, skillset="spot", seq=0, stamp=1.5,
                                                     transition="teleop.start", status=status["spot"])),
        (keys.state(SYSTEM), LiveState(system=SYSTEM, seq=1, stamp=1.5, skillsets=status, event="spot:teleop.start#0")),
        (keys.verdicts(SYSTEM), Verdicts(system=SYSTEM, seq=1, stamp=1.5,
                                         properties=[PropertyVerdict(name="action_guard", holds=True)])),
        (keys.unsafe(SYSTEM), UnsafeReport(system=SYSTEM, seq=1, stamp=1.5, prediction_stale=False, literal_count=3,
                                           unsafe=[UnsafeEntry(skillset="manipulator", transition="arm_ready.start",
                                                               kind="start", controllable=True,
                                                               property="action_guard", constraint="explicit")])),
        (keys.state_space(SYSTEM), StateSpaceReport(system=SYSTEM, stamp=1.6, time=0.01, timeout_reached=False,
                                                    depth=7, markings=440, edges=1200)),
    ]


# -- log format ---------------------------------------------------------------------------


def test_log_round_trip() -> None:
    messages = _messages()
    lines = [log_line(key, m, 100.0 + i) for i, (key, m) in enumerate(messages)]
    data = json.loads(lines[1])
    assert list(data) == ["t", "key", "type", "message"]
    assert data["t"] == 101.0 and data["key"] == "skinet/spot_arm/state" and data["type"] == "LiveState"
    assert data["message"] == messages[1][1].model_dump(mode="json")
    entries = read_log(["", *lines[:2], "   ", *lines[2:]], "log.jsonl")  # blank lines are skipped
    assert entries == [Entry(100.0 + i, key, type(m).__name__, m) for i, (key, m) in enumerate(messages)]


def test_log_line_rejects_what_is_not_a_message() -> None:
    with pytest.raises(ValueError, match="'SkillsetStatus' is not a wire message"):
        log_line("k", SkillsetStatus(), 0.0)


GOOD_BODY = '{"v":1,"system":"s","seq":0,"stamp":0,"skillsets":{}}'
TYPES = ("CanonicalEvent, CheckReply, CheckRequest, Divergences, Heartbeat, LiveState, ModelBundle, PilotGoalReply, "
         "PilotGoalRequest, PilotStatus, PredictReply, PredictRequest, ResultFeed, StateSpaceReport, UnsafeReport, "
         "Verdicts")


@pytest.mark.parametrize("line, error", [
    ("not json", "invalid JSON: Expecting value (column 1)"),
    ('{"t":1,', "invalid JSON: Expecting property name enclosed in double quotes (column 8)"),
    ("[1]", "expected a JSON object, got array"),
    ('"text"', "expected a JSON object, got string"),
    ('{"t":1,"key":"k","type":"LiveState"}', "missing field 'message'"),
    ('{"key":"k","type":"LiveState","message":{}}', "missing field 't'"),
    ('{"t":1,"key":"k","type":"LiveState","message":{},"x":1}', "unexpected field 'x' (fields: t, key, type, message)"),
    ('{"t":"1","key":"k","type":"LiveState","message":{}}', "field 't' must be a finite number, got string"),
    ('{"t":true,"key":"k","type":"LiveState","message":{}}', "field 't' must be a finite number, got boolean"),
    ('{"t":NaN,"key":"k","type":"LiveState","message":{}}', "field 't' must be a finite number, got nan"),
    ('{"t":1,"key":null,"type":"LiveState","message":{}}', "field 'key' must be a string, got null"),
    ('{"t":1,"key":"","type":"LiveState","message":{}}', "field 'key' is empty"),
    ('{"t":1,"key":"k","type":3,"message":{}}', "field 'type' must be a string, got number"),
    ('{"t":1,"key":"k","type":"Foo","message":{}}', f"unknown message type 'Foo' (types: {TYPES})"),
    ('{"t":1,"key":"k","type":"LiveState","message":[]}', "field 'message' must be an object, got array"),
    ('{"t":1,"key":"k","type":"LiveState","message":{}}', "invalid LiveState: system: Field required"),
    ('{"t":1,"key":"k","type":"LiveState","message":' + GOOD_BODY.replace('"v":1', '"v":2') + "}",
     "invalid LiveState: v: Input should be 1"),
    ('{"t":1,"key":"k","type":"LiveState","message":' + GOOD_BODY.replace('"seq":0', '"seq":-1') + "}",
     "invalid LiveState: seq: Input should be greater than or equal to 0"),
])
def test_malformed_log_line(line: str, error: str) -> None:
    good = '{"t":1,"key":"k","type":"LiveState","message":' + GOOD_BODY + "}"
    with pytest.raises(SourceError) as info:
        read_log([good, "", line], "log.jsonl")
    assert str(info.value) == f"log.jsonl:3: error: {error}"


def test_every_malformed_line_is_reported_up_to_a_limit() -> None:
    with pytest.raises(SourceError) as info:
        read_log(["x", "{}", "[]"], "a.jsonl")
    assert str(info.value).splitlines() == [
        "a.jsonl:1: error: invalid JSON: Expecting value (column 1)",
        "a.jsonl:2: error: missing field 't'",
        "a.jsonl:3: error: expected a JSON object, got array",
    ]
    with pytest.raises(SourceError) as info:
        read_log(["x"] * (MAX_ERRORS + 5), "a.jsonl")
    assert len(info.value.diagnostics) == MAX_ERRORS + 1
    assert str(info.value.diagnostics[-1]) == f"a.jsonl: error: too many errors, stopped at line {MAX_ERRORS}"


def test_timeline_command_reports_a_malformed_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "bad.jsonl"
    log.write_text('{"t":1}\nnot json\n')
    assert main(["timeline", str(log), "-o", str(tmp_path / "x.png")]) == 1
    err = capsys.readouterr().err
    assert err == f"{log}:1: error: missing field 'key'\n{log}:2: error: invalid JSON: Expecting value (column 1)\n"
    assert not (tmp_path / "x.png").exists()


def test_timeline_command_draws_an_unfinished_mcap_log(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A recorder killed without warning leaves an MCAP file without its end: drawn, with a warning
    (the warning used to be an internal error, NameError)."""
    from skinet.wire import mcap_log

    monkeypatch.setattr(mcap_log, "CHUNK_SIZE", 2048)
    log = tmp_path / "cut.mcap"
    with log.open("wb") as f:
        writer = mcap_log.McapLogWriter(f)
        for n in range(20):
            for key, message in _messages():
                writer.write(key, message, 100.0 + n)
        writer.finish()
    log.write_bytes(log.read_bytes()[: log.stat().st_size // 2])
    assert main(["timeline", str(log), "-o", str(tmp_path / "cut.png")]) == 0
    out, err = capsys.readouterr()
    assert err.startswith(f"{log}: warning: the MCAP file ends early (recorder stopped without finishing it?): ")
    assert out.startswith("timeline of ") and (tmp_path / "cut.png").exists()


def test_timeline_command_needs_live_states(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "verdicts.jsonl"
    key, message = _messages()[2]
    log.write_text(log_line(key, message, 1.0) + "\n")
    assert main(["timeline", str(log), "-o", str(tmp_path / "x.png")]) == 1
    assert capsys.readouterr().err == f"{log}: error: no LiveState message in the log: nothing to draw\n"


# -- replayed runs as logs and pictures ----------------------------------------------------


@functools.cache
def _run_cached(name: str) -> tuple[System, tuple[Entry, ...]]:
    path = MISSIONS / f"{name}.toml"
    scenario = parse_scenario(read_text(path), str(path))
    system, _ = load_system(path.parent / scenario.system)
    return system, tuple(records_to_log(system, scenario, replay(system, scenario)))


def _run(name: str) -> tuple[System, list[Entry]]:
    """A paper run replayed and turned into its monitor log (computed once per run)."""
    system, entries = _run_cached(name)
    return system, list(entries)


@pytest.fixture(scope="module")
def demo_dirs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``skinet demo --log LOGS --timeline PICS`` run once."""
    logs, pics = tmp_path_factory.mktemp("logs"), tmp_path_factory.mktemp("pics")
    assert main(["demo", "--log", str(logs), "--timeline", str(pics)]) == 0
    return logs, pics


def test_records_to_log_publishes_what_the_monitor_would() -> None:
    system, entries = _run("unassisted")
    assert entries[0].type == "ModelBundle" and entries[0].key == keys.model(SYSTEM, bundle(system).digest)
    assert [e.type for e in entries[1:5]] == ["LiveState", "Verdicts", "UnsafeReport", "StateSpaceReport"]
    states = [e.message for e in entries if isinstance(e.message, LiveState)]
    assert [s.seq for s in states] == list(range(len(states)))
    # The views vouch for a replayed scenario's marking: every skillset live from the start (issue 32, item 8).
    assert {(k, x.state, x.since) for s in states for k, x in s.sync.items()} == {
        ("spot", "live", 0.0), ("manipulator", "live", 0.0)}
    assert all(len(s.sync) == 2 for s in states)
    events = [e.message for e in entries if isinstance(e.message, CanonicalEvent)]
    assert len(events) == len(states) - 1
    for ss in ("spot", "manipulator"):
        assert [e.seq for e in events if e.skillset == ss] == list(range(sum(e.skillset == ss for e in events)))
    assert all(e.t == e.message.stamp for e in entries if hasattr(e.message, "stamp"))
    assert [t for t in (e.t for e in entries)] == sorted(e.t for e in entries)
    assert [(t, p) for t, p in violations(entries)] == [(52.0, "action_guard"), (66.0, "safety_guard"),
                                                      (76.0, "action_guard")]
    assert violations(_run("assisted")[1]) == []


def test_records_to_log_lists_the_divergences_as_the_monitor_does() -> None:
    """Issue 27 item 4: a log's divergence list, so that skinet replay shows it in the views."""
    _, entries = _run("mobile_divergence")
    [listed] = [e for e in entries if e.type == "Divergences"]
    state = next(e.message for e in entries if isinstance(e.message, LiveState) and e.message.divergence)
    assert (listed.key, listed.t, listed.message.older) == (keys.divergences("mobile_manip"), 6.0, 0)
    [d] = listed.message.entries
    assert (d.n, d.kind, d.seq, d.stamp, d.skillset, d.event, d.reason, d.info) == (
        0, "divergence", state.seq, 6.0, "arm", state.event, "'pick.success.picked' is not enabled in the live marking",
        "pick reported done, never started")
    assert not any(e.type == "Divergences" for e in _run("unassisted")[1])


def test_assisted_run_shows_the_paper_warnings() -> None:
    """docs/mission.md: go_to_waypoint.start flagged before trap 2's transfer, arm_ready.start at trap 3."""
    spans = flagged(_run("assisted")[1], 200.0)

    def during(lane: str, t: float) -> bool:
        return any(a <= t < b for a, b in spans.get(lane, []))

    assert during("spot.go_to_waypoint", 58.0)  # considered at step 29 (t = 58 s)
    assert during("manipulator.arm_ready", 74.0)  # considered before step 36 (t = 74 s)
    assert not during("spot.go_to_waypoint", 10.0)  # trap 1's transfer is safe


def test_records_to_log_rejects_records_of_another_scenario() -> None:
    paths = [MISSIONS / "unassisted.toml", MISSIONS / "assisted.toml"]
    first, second = (parse_scenario(read_text(p), str(p)) for p in paths)
    system, _ = load_system(paths[0].parent / first.system)
    with pytest.raises(ValueError, match="do not match the steps of scenario 'unassisted'"):
        records_to_log(system, first, replay(system, second, predict=False), predict=False)


def test_demo_writes_logs_and_pictures(demo_dirs: tuple[Path, Path]) -> None:
    logs, pics = demo_dirs
    for run in ("unassisted", "assisted"):
        entries = read_log(read_text(logs / f"{run}.jsonl").splitlines(), run)
        assert _timeless(entries) == _timeless(_run(run)[1])
        assert _png_size(pics / f"{run}.png")[0] >= 1000


def _timeless(entries: list[Entry]) -> list[Entry]:
    """Entries without exploration times (they differ between runs)."""
    return [Entry(e.t, e.key, e.type, e.message.model_copy(update={"time": 0.0})
                  if isinstance(e.message, StateSpaceReport) else e.message) for e in entries]


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


def test_timeline_command_draws_a_demo_log(demo_dirs: tuple[Path, Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    log = demo_dirs[0] / "unassisted.jsonl"
    out = tmp_path / "timeline.png"
    assert main(["timeline", str(log), "-o", str(out)]) == 0
    assert capsys.readouterr().out == f"timeline of 315 messages written to {out}\n"
    size = out.stat().st_size
    assert 30_000 < size < 3_000_000
    width, height = _png_size(out)
    assert width == 1500 and 800 <= height <= 1400


def _lane_labels(entries: list[Entry], system: System | None = None, render: bool = False) -> list[str]:
    figure = draw(entries, "t", system)
    if render:
        figure.canvas.draw()  # an Agg canvas: the figure really renders
    return [t.get_text() for t in figure.axes[0].get_yticklabels()]


def test_one_lane_per_skill_resource_and_property(paper_system: System) -> None:
    _, entries = _run("unassisted")
    labels = _lane_labels(entries, render=True)
    expected = [f"{c.name} events" for c in paper_system.components]
    for c in paper_system.components:
        expected += [f"{c.name}.{r.name}" for r in c.skillset.resources]
        expected += [f"{c.name}.{k.name}" for k in c.skillset.skills]
    expected += [f"property {p.name}" for p in paper_system.properties]
    assert list(reversed(labels)) == expected  # y ticks go bottom up
    assert len(expected) == 2 + 5 + 10 + 2
    # Without the model bundle, the lanes are what the log shows (skills never run are missing) ...
    observed = [e for e in entries if e.type != "ModelBundle"]
    assert "spot.sit_down" not in _lane_labels(observed)
    assert set(_lane_labels(observed)) <= set(labels)
    # ... unless the system is given.
    assert _lane_labels(observed, paper_system) == labels


def test_recorded_times_are_labelled_to_a_tenth_without_warnings(recwarn: pytest.WarningsRecorder) -> None:
    """A recorded log has receive times like 1700000018.3619: labels show 52.4 s, not 52.3619 s,
    and drawing the status ticks ("|", a marker without a face) gives no matplotlib warning."""
    import dataclasses

    _, entries = _run("unassisted")
    shifted = [dataclasses.replace(e, t=e.t + 0.3619) for e in entries[1:]]  # the first entry keeps t0
    figure = draw([entries[0], *shifted], "recorded")
    top = figure.axes[0]
    assert top.get_title(loc="right") == (
        "3 violations: action_guard at 52.4 s, safety_guard at 66.4 s, action_guard at 76.4 s")
    assert "VIOLATED at 52.4 s" in [t.get_text() for t in top.texts]
    figure.canvas.draw()
    assert [str(w.message) for w in recwarn] == []


def test_timeline_marks_violations_and_unsafe_counts() -> None:
    _, entries = _run("unassisted")
    figure = draw(entries, "unassisted")
    top, low = figure.axes[:2]
    assert top.get_title(loc="right") == (
        "3 violations: action_guard at 52 s, safety_guard at 66 s, action_guard at 76 s")
    texts = [t.get_text() for t in top.texts]
    assert texts.count("VIOLATED at 52 s") == 1 and "VIOLATED at 66 s" in texts
    lines = {line.get_label(): line for line in low.get_lines()}
    operator = lines["operator view (properties that hold now)"]
    literal = lines["literal Algorithm 1 count"]
    assert literal.get_linestyle() == "--"
    reports = [e.message for e in entries if isinstance(e.message, UnsafeReport)]
    assert list(operator.get_ydata())[:len(reports)] == [len(r.unsafe) for r in reports]
    assert list(literal.get_ydata())[:len(reports)] == [r.literal_count for r in reports]
    assert draw(_run("assisted")[1]).axes[0].get_title(loc="right") == "no violation"
    assert lanes_of(entries).properties == ["action_guard", "safety_guard"]


# -- skinet record on a real Zenoh session --------------------------------------------------


def _wait_token(session: zenoh.Session, key_expr: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(r.ok is not None for r in session.liveliness().get(key_expr, timeout=0.5)):
            return
        time.sleep(0.05)
    pytest.fail(f"no liveliness token on {key_expr} within {timeout} s")


@pytest.mark.parametrize("name", ["rec.jsonl", "rec.mcap"])
def test_record_writes_what_is_published(tmp_path: Path, paper_system: System,
                                         capsys: pytest.CaptureFixture[str], name: str) -> None:
    endpoint = free_endpoint()
    out = tmp_path / name
    messages = _messages()
    model = bundle(paper_system)
    result: list[int] = []
    argv = ["record", SYSTEM, "-o", str(out), "--mode", "peer", "--listen", endpoint, "--no-multicast-scouting",
            "--duration", "30", "--count", str(len(messages) + 1)]
    recorder = threading.Thread(target=lambda: result.append(main(argv)), daemon=True)
    t_start = time.time()
    recorder.start()
    session = None
    try:
        deadline = time.monotonic() + 10
        while session is None:
            try:
                session = zenoh.open(session_config("peer", connect=[endpoint], multicast_scouting=False))
            except zenoh.ZError:  # the recorder is not listening yet
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        queryable = session.declare_queryable(
            keys.model(SYSTEM, model.digest), lambda q: q.reply(keys.model(SYSTEM, model.digest), encode(model)))
        _wait_token(session, keys.alive(SYSTEM, "recorder", "*"))
        opts = dict(congestion_control=zenoh.CongestionControl.BLOCK)
        for key, message in messages[:3]:
            session.put(key, encode(message), **opts)
        session.put(keys.unsafe(SYSTEM), b"\xc1 not msgpack", **opts)  # counted and skipped
        session.put(keys.verdicts("other_system"), encode(messages[2][1]), **opts)  # another system: not recorded
        for key, message in messages[3:]:
            session.put(key, encode(message), **opts)
        recorder.join(20)
        queryable.undeclare()
    finally:
        if session is not None:
            session.close()
    assert not recorder.is_alive() and result == [0]
    entries = load_log(str(out))
    published = [e for e in entries if e.type != "ModelBundle"]
    assert [(e.key, e.message) for e in published] == messages
    assert [e.message for e in entries if e.type == "ModelBundle"] == [model]
    assert all(t_start <= e.t <= time.time() for e in entries)
    assert [e.t for e in published] == sorted(e.t for e in published)
    err = capsys.readouterr().err
    assert f"skinet record: skipped undecodable payload on {keys.unsafe(SYSTEM)}: not msgpack" in err
    assert err.endswith(f"skinet record: {len(messages) + 1} messages written to {out} (1 undecodable skipped)\n")
    if name.endswith(".mcap"):  # what Foxglove and other tools read: JSON with JSON schemas, one channel per key
        from mcap.reader import make_reader

        with out.open("rb") as f:
            summary = make_reader(f).get_summary()
        assert summary is not None
        assert {s.name: s.encoding for s in summary.schemas.values()} == {
            e.type: "jsonschema" for e in entries}
        assert {c.topic for c in summary.channels.values()} == {e.key for e in entries}
        assert {c.message_encoding for c in summary.channels.values()} == {"json"}
        assert main(["timeline", str(out), "-o", str(tmp_path / "rec.png")]) == 0
        assert (tmp_path / "rec.png").stat().st_size > 10_000
