"""The command check ``skinet/<system>/check`` (docs/semantics.md §7): policy, verdicts at the paper's
warnings, unknown names, bad payloads, through a real router."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator

import msgpack
import pytest
import zenoh

from services.monitor.check import MAX_NAME, MAX_REQUEST, Policy, parse_command, parse_policy
from services.predictor.service import start_predictor
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import CheckReply, CheckRequest
from tests.services.test_monitor import AG, PAPER_STEPS, SG, Events, Reports
from tests.services.test_monitor import monitor_factory, session, system  # noqa: F401 (fixtures)
from tests.services.conftest import open_client

WARN = "explicit=warn,implicit=warn,forced=warn,unknown=warn,state_unknown=warn,prediction_pending=warn"
STRICT = "explicit=deny,implicit=warn,forced=deny,unknown=warn,state_unknown=deny,prediction_pending=warn"
PENDING = ("", "prediction_pending", "warn", True, None, [])  # the reason of a check before the prediction


def ask(session: zenoh.Session, request: CheckRequest | None = None, parameters: str = "",
        payload: bytes | None = None, timeout: float = 5.0) -> CheckReply:
    selector = keys.check("spot_arm", keys.LOCAL_CLIENT) + (f"?{parameters}" if parameters else "")
    body = payload if payload is not None else (encode(request) if request is not None else None)
    replies = list(session.get(selector, payload=body, timeout=timeout))
    assert len(replies) == 1 and replies[0].ok is not None, replies
    return decode(replies[0].ok.payload.to_bytes(), CheckReply)


def check(session: zenoh.Session, command: str, **fields: object) -> CheckReply:
    return ask(session, parse_command(command).model_copy(update=fields))


def reasons(reply: CheckReply) -> list[tuple]:
    return [(r.property, r.constraint, r.action, r.controllable, r.steps, r.witness) for r in reply.reasons]


@pytest.fixture
def predictor(router: str) -> Iterator[None]:
    """A predictor in this process, on its own client session."""
    psession = open_client(router)
    p = start_predictor(psession, "check")
    yield
    p.close()
    psession.close()


def test_policies() -> None:
    assert str(Policy()) == WARN == str(parse_policy("warn")) == str(parse_policy(""))
    assert str(parse_policy("strict")) == STRICT
    assert str(parse_policy("strict,implicit=deny")) == STRICT.replace("implicit=warn", "implicit=deny")
    assert str(parse_policy("explicit=deny")) == WARN.replace("explicit=warn", "explicit=deny")
    assert str(parse_policy("prediction_pending=deny")) == WARN.replace("pending=warn", "pending=deny")
    assert parse_policy("strict").action("forced") == "deny"
    assert parse_policy("strict").action("some_future_kind") == "warn"
    with pytest.raises(ValueError, match=r"^unknown check policy 'lenient' \(presets: warn, strict; "):
        parse_policy("lenient")
    with pytest.raises(ValueError, match=r"^check policy 'explicit=block': action must be one of allow, warn, deny$"):
        parse_policy("explicit=block")
    for kind in ("state_unknown", "prediction_pending"):  # never a plain allow on what the monitor cannot vouch for
        with pytest.raises(ValueError, match=rf"^check policy '{kind}=allow': {kind} can only be warn or deny "):
            parse_policy(f"{kind}=allow")
    with pytest.raises(ValueError, match=r"^command 'teleop.start' is not of the form skillset:transition"):
        parse_command("teleop.start")


@pytest.mark.parametrize("policy,decision", [(None, "warn"), ("strict", "deny")])
def test_paper_warnings_as_check_answers(monitor_factory, session, system, predictor, policy, decision) -> None:
    reports = Reports(session)
    monitor_factory(system, **({} if policy is None else {"check_policy": parse_policy(policy)}))
    events = Events(session)
    for skillset, transition, _, _ in PAPER_STEPS[:6]:  # arm at RD: paper warning 1
        events.send(skillset, transition)
    reports.step(6)
    reply = check(session, "spot:go_to_waypoint.start", wait=10.0)  # with the prediction of step 6
    assert (reply.ok, reply.decision, reply.enabled, reply.seq) == (True, decision, True, 6)
    assert reasons(reply) == [(SG, "explicit", decision, True, 0, [])]
    assert reply.policy == (WARN if policy is None else STRICT)
    assert (reply.prediction_stale, reply.state_stale) == (False, False)
    safe = check(session, "spot:sit_down.start")
    assert (safe.ok, safe.decision, safe.reasons, safe.enabled) == (True, "allow", [], True)
    idle = check(session, "manipulator:arm_RD_to_HP.success.at_home")  # known, not firable now
    assert (idle.decision, idle.enabled) == ("allow", False)
    # A client (the pilot) may ask under its own policy whatever the monitor's.
    strict = check(session, "spot:go_to_waypoint.start", policy="strict")
    assert (strict.decision, strict.policy) == ("deny", STRICT)
    assert check(session, "spot:sit_down.start", policy="warn").policy == WARN
    bad = check(session, "spot:sit_down.start", policy="lenient")
    assert (bad.ok, bad.decision) == (False, None) and bad.error.startswith("unknown check policy 'lenient'")

    for skillset, transition, _, _ in PAPER_STEPS[6:9]:  # teleop runs: paper warning 2
        events.send(skillset, transition)
    reports.step(9)
    reply = ask(session, parameters="command=manipulator:arm_ready.start")  # the selector form, no waiting
    expected = [(AG, "explicit", decision, True, 0, [])]
    assert (reply.decision, reasons(reply)) == (decision, expected + ([PENDING] if reply.prediction_stale else []))

    events.send(*PAPER_STEPS[9][:2])  # the warning ignored: action_guard violated
    reports.step(10)
    reply = check(session, "spot:teleop.interrupt", wait=10.0)
    assert (reply.decision, reply.violated, reply.recovers, reply.enabled) == ("allow", [AG], [AG], True)


@pytest.mark.parametrize("policy,decision", [(None, "warn"), ("strict", "warn"), ("prediction_pending=deny", "deny")])
def test_a_pending_prediction_is_never_a_plain_allow(monitor_factory, session, system, policy, decision) -> None:
    """No predictor: implicit constraints are unknown, so a command nothing else warns about is at least
    warned about, and waiting for the prediction ends at the request's bound with the same answer."""
    monitor_factory(system, **({} if policy is None else {"check_policy": parse_policy(policy)}))
    Events(session)
    reply = check(session, "spot:init_power.start")
    assert (reply.ok, reply.decision, reply.prediction_stale, reply.state_stale) == (True, decision, True, False)
    assert reasons(reply) == [(*PENDING[:2], decision, *PENDING[3:])]
    assert reply.reasons[0].reason == "implicit constraints at step 0 are not known yet: its prediction is pending"
    t0 = time.monotonic()
    waited = check(session, "spot:init_power.start", wait=0.5)
    assert 0.5 <= time.monotonic() - t0 < 2.0 and waited.decision == decision


def test_unknown_names_and_bad_requests_get_one_line_errors(monitor_factory, session, system) -> None:
    monitor = monitor_factory(system)
    reply = check(session, "spt:teleop.start")
    assert (reply.ok, reply.decision, reply.error, reply.candidates) == (False, None, "unknown skillset 'spt'", ["spot"])
    reply = check(session, "spot:telop.start")
    assert reply.error == "unknown transition 'telop.start' of skillset 'spot'"
    assert reply.candidates[0] == "teleop.start" and len(reply.candidates) <= 8
    reply = ask(session, payload=b"\xc1garbage")
    assert (reply.ok, reply.error) == (False, "not msgpack: FormatError")
    reply = ask(session, payload=encode(CheckReply(system="x", skillset="", transition="", ok=False)))
    assert reply.error.startswith("invalid CheckRequest: ")
    reply = ask(session)
    assert reply.error == ("empty check request: send a CheckRequest payload or the parameter "
                           "command=skillset:transition")
    reply = ask(session, parameters="command=teleop")
    assert reply.error.startswith("command 'teleop' is not of the form skillset:transition")
    reply = ask(session, payload=msgpack.packb({"v": 1, "skillset": "spot", "transition": "teleop.start", "wait": 31}))
    assert reply.error == "invalid CheckRequest: wait: Input should be less than or equal to 30"
    # Oversized requests are refused before decoding, names too long for suggestions get none.
    reply = ask(session, payload=b"\x00" * (MAX_REQUEST + 1))
    assert (reply.ok, reply.error) == (False, f"check request of {MAX_REQUEST + 1} bytes refused (limit "
                                              f"{MAX_REQUEST} bytes)")
    reply = ask(session, parameters="command=spot:" + "x" * MAX_REQUEST)
    assert reply.error == f"check request of {MAX_REQUEST + 13} bytes refused (limit {MAX_REQUEST} bytes)"
    long = "y" * (MAX_NAME + 1)
    reply = check(session, f"spot:{long}")
    assert reply.error == (f"unknown transition '{long[:MAX_NAME]}... ({MAX_NAME + 1} characters)' of skillset "
                           "'spot'")
    assert reply.candidates == sorted({t.name for t in system.component("spot").net.transitions})[:8]
    assert len(reply.transition) < MAX_NAME + 30
    c = monitor.check_counters
    assert (c.oversized, c.errors, c.rate_limited) == (2, 8, 0)
    # The monitor is still fine; with neither a bridge nor a predictor it vouches for nothing.
    reply = check(session, "spot:init_power.start")
    assert (reply.decision, reasons(reply)) == ("warn", [("", "state_unknown", "warn", True, None, []), PENDING])
    assert reply.state_stale and reply.state_reason == reply.reasons[0].reason.split("known: ", 1)[1]
    assert re.fullmatch(r"spot syncing since \d\d:\d\d:\d\d: no bridge answered the resync query; "
                        r"manipulator syncing since \d\d:\d\d:\d\d: no bridge answered the resync query",
                        reply.state_reason), reply.state_reason


def test_example_client_asks_before_every_start(router, session, client_factory, spot_arm) -> None:
    """examples/check_client.py against simulated managers, the bridge and a monitor."""
    import subprocess
    import sys

    from chains.chain import embedded_services
    from services.bridge_ros2 import start_bridge
    from services.simulator import Simulator
    from tests.services.conftest import REPO, client_args

    system, typemap = spot_arm
    services_session = client_factory()
    # the predictor: allow needs a fresh prediction
    with embedded_services(services_session, system, True) as (_, monitor, services):
        simulator = Simulator(services_session, system, typemap)
        services.append(simulator)
        services.append(start_bridge(services_session, system, typemap))

        def client(*commands: str) -> subprocess.CompletedProcess:
            return subprocess.run([sys.executable, "examples/check_client.py", "skillsets/spot_arm.toml", *commands,
                                   *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)

        def running(skillset: str, skill: str) -> bool:
            import time

            deadline = time.monotonic() + 5
            while time.monotonic() < deadline:
                if simulator.skill_status(skillset, skill)[0] and monitor.check(
                        CheckRequest(skillset=skillset, transition=f"{skill}.interrupt")).enabled:
                    return True
                time.sleep(0.02)
            return False

        out = client("spot:init_power.start")
        assert out.returncode == 0 and out.stdout.startswith("spot:init_power.start: sent (id "), out
        assert running("spot", "init_power")
        out = client("manipulator:arm_ready.start", "manipulator:arm_redy.start")
        assert out.returncode == 1
        lines = out.stdout.splitlines()
        assert lines[:2] == [
            "manipulator:arm_ready.start: NOT SENT (warn: action_guard explicit)",
            "manipulator:arm_redy.start: NOT SENT (check failed: unknown transition 'arm_redy.start' of skillset "
            "'manipulator')",
        ]
        assert lines[2].startswith("  did you mean: arm_ready.start, ") and len(lines) == 3
        assert not simulator.skill_status("manipulator", "arm_ready")[0]
        out = client("manipulator:arm_ready.start", "--force")
        assert out.stdout.startswith("manipulator:arm_ready.start: sent (id ") and \
            out.stdout.rstrip().endswith("check: warn, action_guard explicit)"), out
        assert running("manipulator", "arm_ready")


@pytest.mark.parametrize("policy,decision", [(None, "warn"), ("strict", "deny")])
def test_forced_constraint_is_denied_under_the_strict_policy(monitor_factory, session, policy, decision) -> None:
    """The mobile manipulator (skillsets/mobile_manip.toml): driving off while the arm unfolds is
    forced for stowed_drive (docs/semantics.md §6.3), known at once without any predictor."""
    from skinet.system.load import load_system
    from tests.services.conftest import REPO

    mobile = load_system(REPO / "skillsets" / "mobile_manip.toml")[0]
    reports = Reports(session, mobile.name)
    monitor_factory(mobile, **({} if policy is None else {"check_policy": parse_policy(policy)}))
    events = Events(session, mobile.name)
    for skillset, transition in (("base", "undock.start"), ("base", "undock.success.undocked"),
                                 ("arm", "unfold.start")):
        events.send(skillset, transition)
    reports.step(3)
    replies = list(session.get(keys.check(mobile.name, keys.LOCAL_CLIENT), payload=encode(parse_command("base:navigate.start")),
                               timeout=5.0))
    reply = decode(replies[0].ok.payload.to_bytes(), CheckReply)
    assert (reply.ok, reply.decision, reply.enabled, reply.prediction_stale) == (True, decision, True, True)
    assert [(r.property, r.constraint, r.action, r.steps, r.witness) for r in reply.reasons] == [
        ("stowed_drive", "forced", decision, 1, ["arm:unfold.success.unfolded"]),
        ("", "prediction_pending", "warn", None, [])]
    assert reply.reasons[0].reason


def test_a_resync_query_nobody_answers_is_named_with_its_key_and_timeout(monitor_factory, session, system) -> None:
    """Issue 30: a frozen bridge made the reason "spot syncing since …: Timeout" (Zenoh's bare error)."""
    frozen = session.declare_queryable(keys.resync("spot_arm", "spot"), zenoh.handlers.FifoChannel(64))
    try:
        monitor_factory(system, resync_timeout=0.5)
        expected = re.compile(r"spot syncing since \d\d:\d\d:\d\d: the resync query to the bridge on "
                              r"skinet/spot_arm/resync/spot got no answer within 0\.5 s \(Timeout\); "
                              r"manipulator syncing since \d\d:\d\d:\d\d: no bridge answered the resync query")
        deadline = time.monotonic() + 30
        seen: list[str] = []
        while not (seen and expected.fullmatch(seen[-1])) and time.monotonic() < deadline:
            reply = check(session, "spot:init_power.start")
            if not seen or seen[-1] != reply.state_reason:
                seen.append(reply.state_reason)
            time.sleep(0.05)
        assert expected.fullmatch(seen[-1]), seen
        assert not any(r.endswith(": Timeout") or ": Timeout;" in r for r in seen), seen  # never bare
    finally:
        frozen.undeclare()
