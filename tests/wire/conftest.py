"""One realistic instance of every wire message (docs/semantics.md §1), built from the paper's system."""

from __future__ import annotations

import pytest
from pydantic import BaseModel

from skinet.system.model import System
from skinet.verify.predict import forecast
from skinet.wire.convert import bundle, marking_of, risks, state_space_report, statuses
from skinet.wire.messages import (
    CanonicalEvent, CheckReason, CheckReply, CheckRequest, Divergence, Divergences, FedResult, Heartbeat,
    HeartbeatSkillset, LiveState, MissedOutcome, PilotCommand, PilotGoalReply, PilotGoalRequest, PilotStatus, PlanBranch,
    PlanStep, PredictReply, PredictRequest, PropertyVerdict, RecoveryEntry, ResultFeed, SkillsetStatus, SkillsetSync,
    UnsafeEntry, UnsafeReport, Verdicts,
)

# Arm moving (mutex Busy): starting Spot would break action_guard in one step.
ARM_READY = {"manipulator": {"resources": {"mutex": "Busy", "arm_status": "Away"}, "running": ["arm_ready"]}}


def sample_messages(system: System) -> dict[str, BaseModel]:
    """Message name -> an instance with every optional part filled in."""
    live = {k: SkillsetStatus.model_validate(v) for k, v in ARM_READY.items()}
    marking = marking_of(system, live)
    fc = forecast(system, marking, budget=5.0)
    found = risks(system, marking, fc)
    assert found, "the sample marking should have at least one risk"
    report = state_space_report(system, fc, 1700000000.5)
    b = bundle(system)
    skillsets = statuses(system, marking)
    out: dict[str, BaseModel] = {
        "CanonicalEvent": CanonicalEvent(
            system=system.name, skillset="manipulator", seq=7, stamp=1700000000.25, source="bridge-1",
            transition="arm_ready.start", status=skillsets["manipulator"], info="ok id=3", restart=True,
            divergence="/arm/_action/status: goal 1 ACCEPTED: arm_ready started, but the model says it cannot",
            missed=[MissedOutcome(skillset="manipulator", skill="arm_joystick", gap="the link was down 12.4 s")]),
        "LiveState": LiveState(system=system.name, seq=8, stamp=1700000000.3, skillsets=skillsets,
                               event="manipulator:arm_ready.start#7", divergence="no transition explains it",
                               sync={"spot": SkillsetSync(state="live", since=1700000000.1, source="bridge_ros2/b1"),
                                     "manipulator": SkillsetSync(state="lost", since=1700000000.2,
                                                                 reason="its manager left", source="bridge_ros2/b1")},
                               missed=[MissedOutcome(skillset="spot", skill="teleop", gap="the link was down 12.4 s",
                                                     candidates=["teleop.success.done", "teleop.failure.link_lost"])]),
        "Verdicts": Verdicts(system=system.name, seq=8, stamp=1700000000.3,
                             properties=[PropertyVerdict(name="action_guard", holds=True)]),
        "UnsafeReport": UnsafeReport(
            system=system.name, seq=8, stamp=1700000000.3,
            unsafe=[UnsafeEntry(skillset="spot", transition="init_power.start", kind="start", controllable=True,
                                property="action_guard", constraint="implicit", steps=1,
                                witness=["spot:init_power.start"])],
            recovery=[RecoveryEntry(property="action_guard", skillset="manipulator", transition="arm_ready.end",
                                    controllable=False)],
            violated=["safety_guard"], literal_count=12, prediction_stale=False, state_stale=True,
            state_reason="manipulator lost since 22:13:20: its manager left", stale_since=1700000000.2),
        "StateSpaceReport": report,
        "ModelBundle": b.model_copy(update={"commanded": {"spot": ["battery_low"]}}),  # as a bound system sends it
        "PredictRequest": PredictRequest(system=system.name, digest=b.digest, seq=3, skillsets=skillsets, budget=0.5),
        "PredictReply": PredictReply(system=system.name, digest=b.digest, seq=3, ok=True, instance="p1",
                                     report=report, risks=found),
        "CheckRequest": CheckRequest(skillset="spot", transition="init_power.start", wait=2.5, policy="strict"),
        "CheckReply": CheckReply(
            system=system.name, skillset="spot", transition="init_power.start", ok=True, decision="deny",
            reasons=[CheckReason(property="action_guard", constraint="forced", action="deny", controllable=True,
                                 steps=2, witness=["spot:init_power.success.powered_on"],
                                 reason="init_power may succeed")],
            enabled=True, violated=["safety_guard"], recovers=["safety_guard"], prediction_stale=False, seq=8,
            policy="explicit=deny,implicit=warn,forced=deny,unknown=warn", error="", candidates=["x"],
            state_stale=True, state_reason="manipulator lost since 22:13:20: its manager left"),
        "Heartbeat": Heartbeat(system=system.name, source="bridge_ros2/b1", epoch=1700000000000, period=0.5,
                               token="skinet/spot_arm/alive/bridge_ros2/b1",
                               skillsets={"spot": HeartbeatSkillset(seq=12, manager=True),
                                          "manipulator": HeartbeatSkillset()},
                               pending={"spot": "its manager restarted (the manager (or its gateway) came back): "
                                                "waiting for its new status"}),
        "Divergences": Divergences(system=system.name, monitor="m1", stamp=1700000000.5, older=3, entries=[
            Divergence(n=3, kind="divergence", seq=4, stamp=1700000000.4, skillset="manipulator",
                       event="manipulator:arm_ready.success.ready#7",
                       reason="'arm_ready.success.ready' is not enabled in the live marking"),
            Divergence(n=4, kind="restart", seq=4, stamp=1700000000.45, skillset="spot", event="spot:status#9",
                       info="manager restarted (skill ids reset: teleop); state now differs: power_status "
                            "PowerOn -> PowerOff")]),
        "PilotGoalRequest": PilotGoalRequest(system=system.name, goals=["run spot:go_to_waypoint"],
                                             inputs={"go_to_waypoint": {"target": {"x": 12.0, "y": 3.5, "z": 0.0}}},
                                             mode="drive", max_retries=2, answer="rerun", recover=True,
                                             interrupt=True),
        "PilotGoalReply": PilotGoalReply(system=system.name, accepted=True, goal_id=1, answer="cyclic", moves=4,
                                         steps=[_STEP]),
        "PilotStatus": PilotStatus(system=system.name, pilot="p1", seq=3, stamp=1700000000.6, state="driving",
                                   goal_id=1, client="operator", mode="drive", goals=["reach spot:Standing"],
                                   answer="cyclic", moves_left=3, next=PilotCommand(skillset="spot",
                                                                                    transition="init_power.start"),
                                   steps=[_STEP], retries={"spot:init_power": 1}, commands=1, state_seq=7,
                                   unknown=MissedOutcome(skillset="spot", skill="teleop",
                                                         gap="while the monitor was restarted",
                                                         candidates=["teleop.success.done", "teleop.failure.link_lost"]),
                                   notes=["spot:teleop ended while the monitor was restarted: outcome unknown"],
                                   interrupts={"spot:stand_up": "sent", "manipulator:arm_ready": "not interrupted"}),
    }
    out["ResultFeed"] = ResultFeed(system=system.name, monitor="m1", seq=4, round=0.25, skipped=12, results=[
        FedResult(kind=kind, message=out[name].model_dump(mode="json"))
        for kind, name in (("divergences", "Divergences"), ("state", "LiveState"), ("verdicts", "Verdicts"))])
    return out


_STEP = PlanStep(number="1", skillset="spot", action="init_power.start", branches=[
    PlanBranch(skillset="spot", transition="init_power.failure.power_failure", then="retry", step="1")])


@pytest.fixture(scope="session")
def samples(paper_system: System) -> dict[str, BaseModel]:
    return sample_messages(paper_system)
