"""The simulated skillset managers (services/simulator; corpus README manager behaviour).

Unit tests drive :class:`~services.simulator.manager.Manager` directly and read the
messages it would publish; the last tests run it on Zenoh behind a loopback
router, with the scenario driver sending requests like an operator GUI.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest
import zenoh

from services.simulator import Manager, Simulator, StepRun
from services.simulator.driver import plan
from skinet.lang.parser import parse_skillset
from skinet.mission.scenario import Scenario, Step, parse_scenario
from skinet.ros.interfaces import EVENT_RESULTS, RESULTS, SKILL_STATES
from skinet.ros.keys import KeyStyle, manager_topics
from skinet.ros.typestore import build_typestore, decode, msg_typename, to_plain

R, E, S = RESULTS, EVENT_RESULTS, SKILL_STATES

LAB = """
skillset lab {
    resource {
        power { state { On Off } initial On transition all }
        lamp { state { Lit Dark } initial Lit transition all }
        arm { state { Home Away Moving } initial Home transition { Home -> Moving Moving -> Away Away -> Home } }
        x { state { X0 X1 } initial X0 transition all }
        y { state { Y0 Y1 } initial Y0 transition all }
    }
    event {
        cut { guard power == On effect power -> Off }
        restore { guard power == Off effect power -> On }
        fling { effect arm -> Away }
    }
    skill heater {
        invariant { powered { guard power == On effect lamp -> Dark } }
    }
    skill reader {
        invariant { lit { guard lamp == Lit } }
    }
    skill both {
        invariant {
            first { guard power == On effect x -> X1 }
            second { guard power == On effect y -> Y1 }
        }
    }
    skill reach {
        precondition { on: power == On }
        start { arm -> Moving }
        interrupt { interrupting true effect arm -> Away postcondition arm == Home }
        success there { effect arm -> Away }
    }
}
"""


def lab_manager() -> Manager:
    ss = parse_skillset(LAB, "lab.rl")
    return Manager(ss, build_typestore(ss, {}), info="/lab/lab_skillset_manager", clock=lambda: 5.5)


def spot_manager(spot_arm) -> Manager:
    system, typemap = spot_arm
    ss = system.component("spot").skillset
    return Manager(ss, build_typestore(ss, typemap), info="/spot/spot_skillset_manager", clock=lambda: 5.5)


def plain(messages) -> list[tuple[str, dict[str, Any]]]:
    """(last topic chunk or 'skill/response', message as dicts) for each published message."""
    out = []
    for m in messages:
        topic = m.topic.split("/", 1)[1]
        out.append((topic, to_plain(m.msg)))
    return out


def status_view(msg: dict[str, Any]) -> tuple[dict[str, str], dict[str, tuple[int, str]]]:
    resources = {r["name"]: r["state"] for r in msg["resources"]}
    skills = {v["name"]: (v["state"], v["id"]) for k, v in msg.items() if k.startswith("skill_")}
    return resources, skills


def test_precondition_failure_has_one_bool_per_precondition(spot_arm):
    m = spot_manager(spot_arm)
    [(t1, resp), (t2, status)] = plain(m.skill_request("teleop", "t1"))
    assert (t1, t2) == ("skill/teleop/response", "status")
    assert resp["result"] == R["PRECONDITION_FAILURE"] and resp["id"] == "t1"
    assert (resp["standing"], resp["free"], resp["powered"]) == (False, True, False)
    assert (resp["effect"], resp["name"]) == (False, "")
    # Quirk of the generated manager: the rejected id stays in the READY skill's status.
    _, skills = status_view(status)
    assert skills["teleop"] == (S["READY"], "t1")


def test_start_success_has_no_response_and_status_shows_running(spot_arm):
    m = spot_manager(spot_arm)
    [(topic, status)] = plain(m.skill_request("init_power", "i1"))
    assert topic == "status"
    resources, skills = status_view(status)
    assert skills["init_power"] == (S["RUNNING"], "i1") and resources["control_mode"] == "Busy"
    assert status["info"] == "/spot/spot_skillset_manager"
    assert status["stamp"] == {"sec": 5, "nanosec": 500_000_000}


def test_already_running_carries_the_running_id(spot_arm):
    m = spot_manager(spot_arm)
    m.skill_request("init_power", "i1")
    [(_, resp), (_, status)] = plain(m.skill_request("init_power", "i2"))
    assert resp["result"] == R["ALREADY_RUNNING"] and resp["id"] == "i1"
    assert status_view(status)[1]["init_power"] == (S["RUNNING"], "i1")


def test_illegal_start_effects_give_start_failure():
    m = lab_manager()
    m.skill_request("reach", "r1")
    m.terminate("reach", "success", "there")  # arm Away: Away -> Moving is not declared
    [(_, resp), (_, status)] = plain(m.skill_request("reach", "r2"))
    assert (resp["result"], resp["id"], resp["effect"], resp["on"]) == (R["START_FAILURE"], "r2", False, True)
    resources, skills = status_view(status)
    assert resources["arm"] == "Away" and skills["reach"] == (S["READY"], "r2")


def test_termination_with_effects_and_postcondition(spot_arm):
    m = spot_manager(spot_arm)
    m.skill_request("init_power", "i1")
    [(_, resp), (_, status)] = plain(m.terminate("init_power", "success", "powered_on"))
    assert (resp["result"], resp["name"], resp["id"]) == (R["SUCCESS"], "powered_on", "i1")
    assert (resp["effect"], resp["postcondition"]) == (True, True)
    # The simulated world makes the postcondition true, as the net's transition does.
    resources, skills = status_view(status)
    assert resources == {"power_status": "PowerOn", "posture": "Sitting", "control_mode": "Idle"}
    assert skills["init_power"] == (S["READY"], "i1")
    assert m.terminate("init_power", "failure", "no_battery") == []  # not running any more
    with pytest.raises(ValueError, match="no success mode 'nope'"):
        m.terminate("init_power", "success", "nope")


def test_event_guard_and_effect_failures():
    m = lab_manager()
    [(_, resp), (_, _)] = plain(m.event_request("e1", "restore"))
    assert (resp["id"], resp["response"]) == ("e1", E["GUARD_FAILURE"])
    [(_, resp), (_, status)] = plain(m.event_request("e2", "fling"))  # Home -> Away is not declared
    assert resp["response"] == E["EFFECT_FAILURE"] and status_view(status)[0]["arm"] == "Home"
    [(_, resp), (_, _)] = plain(m.event_request("e3", "warp"))
    assert resp["response"] == E["UNDEFINED"]
    [(_, resp), (_, status)] = plain(m.event_request("e4", "cut"))
    assert resp["response"] == E["SUCCESS"] and status_view(status)[0]["power"] == "Off"


def test_invariant_cascade_responses():
    """cut stops heater (its effect darkens the lamp), which then stops reader: responses in order."""
    m = lab_manager()
    m.skill_request("heater", "h1")
    m.skill_request("reader", "r1")
    out = plain(m.event_request("e1", "cut"))
    assert [t for t, _ in out] == ["skill/heater/response", "skill/reader/response", "event_response", "status"]
    heater, reader, event, status = (msg for _, msg in out)
    assert (heater["result"], heater["name"], heater["effect"], heater["id"]) == (R["INVARIANT_FAILURE"], "powered", True, "h1")
    assert (reader["result"], reader["name"], reader["effect"]) == (R["INVARIANT_FAILURE"], "lit", False)
    assert event["response"] == E["SUCCESS"]
    resources, skills = status_view(status)
    assert resources["lamp"] == "Dark" and skills["heater"][0] == skills["reader"][0] == S["READY"]


def test_every_violated_invariant_applies_its_effects_and_the_last_is_named():
    m = lab_manager()
    m.skill_request("both", "b1")
    out = plain(m.raise_event("cut"))
    both, event, status = (msg for _, msg in out)
    assert (both["result"], both["name"], both["effect"]) == (R["INVARIANT_FAILURE"], "second", True)
    assert status_view(status)[0] | {} == {"power": "Off", "lamp": "Lit", "arm": "Home", "x": "X1", "y": "Y1"}
    # Raised by the implementation: the response id is the status info.
    assert event["id"] == status["info"] == "/lab/lab_skillset_manager"


def test_interrupting_skill_and_interrupt_ids():
    m = lab_manager()
    m.skill_request("reach", "r1")
    assert m.interrupt("reach", "other") == []  # not the running id: ignored
    [(_, status)] = plain(m.interrupt("reach", "r1"))
    assert status_view(status)[1]["reach"] == (S["INTERRUPTING"], "r1")
    assert m.terminate("reach", "success", "there") == []  # only a RUNNING skill terminates
    [(_, resp), (_, status)] = plain(m.interrupted("reach"))
    assert (resp["result"], resp["id"], resp["effect"], resp["postcondition"]) == (R["INTERRUPT"], "r1", True, True)
    # Effects (arm -> Away) then the postcondition made true by the world (arm == Home).
    resources, skills = status_view(status)
    assert resources["arm"] == "Home" and skills["reach"] == (S["READY"], "r1")
    assert m.interrupt("reach", "r1") == []  # not running


def test_plan_of_scenario_steps(spot_arm):
    ss = spot_arm[0].component("spot").skillset
    assert plan(ss, Step(0, "spot", "teleop.start")).action == "start"
    assert plan(ss, Step(0, "spot", "teleop.interrupt")).action == "interrupt"
    p = plan(ss, Step(0, "spot", "teleop.failure.link_lost"))
    assert (p.action, p.skill, p.name) == ("failure", "teleop", "link_lost")
    assert plan(ss, Step(0, "spot", "power_switchoff")).action == "event"
    assert plan(ss, Step(0, "spot", consider="teleop.start")).action == "consider"
    for bad in ("teleop.inv.powered", "fly.start", "teleop.success.nope", "teleop"):
        with pytest.raises(ValueError):
            plan(ss, Step(0, "spot", bad))


# -- on Zenoh ------------------------------------------------------------------------------


class StatusLog:
    """Every SkillsetStatus and response published by a system's simulated managers."""

    def __init__(self, session: zenoh.Session, system, typemap, style: KeyStyle = KeyStyle()):
        self.items: list[tuple[str, str, dict[str, Any], bytes | None]] = []
        self._cond = threading.Condition()
        self._subs = []
        for c in system.components:
            store = build_typestore(c.skillset, typemap)
            topics = {t.topic: t for t in manager_topics(c.skillset)}

            def on_sample(sample, c=c, store=store, topics=topics):
                t = topics.get(style.topic(c.manager, str(sample.key_expr)) or "")
                if t is None or t.kind not in ("status", "skill_response", "event_response"):
                    return
                msg = to_plain(decode(store, t.typename, sample.payload.to_bytes()))
                att = sample.attachment.to_bytes() if sample.attachment is not None else None
                with self._cond:
                    self.items.append((c.name, t.topic, msg, att))
                    self._cond.notify_all()

            self._subs.append(session.declare_subscriber(style.all_topics(c.manager, c.skillset), on_sample))

    def wait(self, count: int, timeout: float = 5.0) -> list:
        with self._cond:
            assert self._cond.wait_for(lambda: len(self.items) >= count, timeout), self.items
            return list(self.items)


SHORT = """
[scenario]
name = "short"
system = "spot_arm.toml"

[[steps]]
t = 0.0
skillset = "spot"
transition = "init_power.start"

[[steps]]
t = 0.1
skillset = "spot"
consider = "stand_up.start"

[[steps]]
t = 0.2
skillset = "spot"
transition = "init_power.success.powered_on"

[[steps]]
t = 0.3
skillset = "manipulator"
transition = "arm_ready.start"

[[steps]]
t = 0.4
skillset = "manipulator"
transition = "arm_ready.interrupt"

[[steps]]
t = 0.5
skillset = "spot"
transition = "power_switchoff"
"""


def test_driver_plays_a_scenario_over_zenoh(client_factory, spot_arm):
    system, typemap = spot_arm
    scenario = parse_scenario(SHORT, "short.toml")
    sim_session, watcher = client_factory(), client_factory()
    log = StatusLog(watcher, system, typemap)
    sim = Simulator(sim_session, system, typemap)
    time.sleep(0.5)  # the watcher's subscription reaches the simulator's session
    seen: list[StepRun] = []
    started = time.monotonic()
    runs = sim.drive(scenario, speed=2.0, on_step=seen.append)
    assert time.monotonic() - started >= 0.25  # t = 0.5 at speed 2
    assert seen == runs and [r.action for r in runs] == ["start", "consider", "success", "start", "interrupt", "event"]
    assert [r.ok for r in runs] == [True] * 6
    assert runs[0].detail == "short-1" and runs[4].detail == "short-3"  # the interrupt uses the running id (step 3: the consider is no step)
    items = log.wait(9)
    spot = [(t.split("/", 1)[1], m) for ss, t, m, _ in items if ss == "spot"]
    arm = [(t.split("/", 1)[1], m) for ss, t, m, _ in items if ss == "manipulator"]
    assert [t for t, _ in spot] == ["status", "skill/init_power/response", "status", "event_response", "status"]
    assert status_view(spot[-1][1])[0] == {"power_status": "PowerOff", "posture": "Sitting", "control_mode": "Idle"}
    assert spot[3][1] == {"id": "short-5", "response": E["SUCCESS"]}
    # arm_ready is "interrupting true": INTERRUPTING, then the implementation finishes it.
    assert [t for t, _ in arm] == ["status", "status", "skill/arm_ready/response", "status"]
    assert status_view(arm[1][1])[1]["arm_ready"] == (S["INTERRUPTING"], "short-3")
    assert arm[2][1]["result"] == R["INTERRUPT"]
    assert status_view(arm[3][1])[0] == {"mutex": "Free", "arm_status": "Away"}
    sim.close()


def test_status_request_and_rmw_zenoh_keys(client_factory, spot_arm):
    system, typemap = spot_arm
    style = KeyStyle(rmw_zenoh=True, domain=5)
    sim_session, peer = client_factory(), client_factory()
    sim = Simulator(sim_session, system, typemap, style=style)
    log = StatusLog(peer, system, typemap, style)
    keys_seen: list[str] = []
    sub = peer.declare_subscriber("5/spot/**", lambda s: keys_seen.append(str(s.key_expr)))
    comp = system.component("spot")
    store = build_typestore(comp.skillset, typemap)
    req = next(t for t in manager_topics(comp.skillset) if t.kind == "status_request")
    time.sleep(0.5)
    peer.put(style.key(comp.manager, req, store), b"\x00\x01\x00\x00\x00")  # std_msgs/Empty in CDR
    assert sim.wait_handled("spot", req.topic, 1)
    [(ss, topic, status, attachment)] = log.wait(1)
    assert (ss, topic) == ("spot", "spot_skillset/status") and status["info"] == comp.manager
    assert attachment is not None and len(attachment) == 33 and attachment[16] == 16
    typename = msg_typename(comp.skillset, "SkillsetStatus")
    assert f"5/spot/spot_skillset_manager/spot_skillset/status/spot_skillset_interfaces::msg::dds_::SkillsetStatus_/" \
           f"{store.hash_rihs01(typename)}" in keys_seen
    sub.undeclare()
    sim.close()


def test_driver_rejects_unknown_names_before_sending(client_factory, spot_arm):
    system, typemap = spot_arm
    sim = Simulator(client_factory(), system, typemap)
    bad = Scenario("bad", "spot_arm.toml", (Step(0, "spot", "init_power.start"), Step(1, "spot", "fly.start")))
    with pytest.raises(ValueError, match="step 2"):
        sim.drive(bad, speed=0)
    assert sim.skill_status("spot", "init_power") == (False, "")
    sim.close()


def test_the_world_ends_each_started_skill_as_the_outcomes_say(client_factory, spot_arm):
    """services/simulator/world.py: a pilot starts skills and no scenario step ends them; the simulated
    implementations do, in the favourable mode or the failure declared for that run of that skill."""
    from services.simulator.driver import Operator
    from services.simulator.world import End, World
    from skinet.pilot.run import Failure, Outcomes
    from skinet.ros.requests import skill_interrupt, skill_request

    system, typemap = spot_arm
    sim = Simulator(client_factory(), system, typemap)
    log = StatusLog(client_factory(), system, typemap)
    world = World(sim, Outcomes(system, [Failure("manipulator", "arm_ready", 1, "blocked")]))
    operator = Operator(client_factory(), sim)
    node = sim.nodes["manipulator"]
    time.sleep(0.5)  # the operator's and the log's declarations reach the simulator's session

    def start(skill: str, id_: str) -> None:
        assert operator.send("manipulator", skill_request(node.store, node.component.skillset, skill, id_))
        deadline = time.monotonic() + 5
        while not world.idle():
            assert time.monotonic() < deadline, world.ends
            time.sleep(0.01)

    try:
        for skill, id_ in [("arm_ready", "a1"), ("arm_moving_to_RD", "a2"), ("arm_RD_to_HP", "a3"),
                           ("arm_ready", "a4")]:
            start(skill, id_)
        assert world.ends == [End("manipulator", "arm_ready", "a1", "failure", "blocked", True),
                              End("manipulator", "arm_moving_to_RD", "a2", "success", "at_ready", True),
                              End("manipulator", "arm_RD_to_HP", "a3", "success", "at_home", True),
                              End("manipulator", "arm_ready", "a4", "success", "ready", True)]
        responses = [(t.split("/")[-2], m["id"], m["result"], m["name"]) for ss, t, m, _ in log.wait(12)  # 3 a start
                     if ss == "manipulator" and t.endswith("/response")]
        assert responses == [("arm_ready", "a1", R["FAILURE"], "blocked"),
                             ("arm_moving_to_rd", "a2", R["SUCCESS"], "at_ready"),  # topics are lower case
                             ("arm_rd_to_hp", "a3", R["SUCCESS"], "at_home"),
                             ("arm_ready", "a4", R["SUCCESS"], "ready")]
        # An execution stopped otherwise before its end is left alone (the interrupt comes first).
        world.duration = 1.0
        assert operator.send("manipulator", skill_request(node.store, node.component.skillset, "arm_RD_to_HP", "a5"))
        assert operator.send("manipulator", skill_interrupt(node.store, node.component.skillset, "arm_RD_to_HP", "a5"))
        start("arm_moving_to_RD", "a6")  # the arm is Away: to RD again, while a5's end is still due
        assert world.ends[4:] == [End("manipulator", "arm_RD_to_HP", "a5", "success", "at_home", False),
                                  End("manipulator", "arm_moving_to_RD", "a6", "success", "at_ready", True)]
        assert sim.skill_status("manipulator", "arm_RD_to_HP") == (False, "a5")
    finally:
        world.close()
        operator.close()
        sim.close()


def test_stamps_past_2038_are_clamped_with_one_warning(spot_arm, caplog) -> None:
    """Issue 30: ROS Time seconds are int32; a clock past 2038-01-19 made the status fail to encode."""
    from skinet.ros.stamp import ros_time
    from skinet.ros.typestore import encode

    assert ros_time(1.25) == (1, 250_000_000, "")
    assert ros_time(2**31 - 0.5) == (2**31 - 1, 500_000_000, "")
    assert ros_time(2**31 + 5.0) == (2**31 - 1, 999_999_999, "stamp 2147483653 s is past the int32 seconds of ROS "
                                                               "Time (2038-01-19 03:14:07 UTC): clamped to it")
    assert ros_time(float("inf"))[:2] == (0, 0)
    system, typemap = spot_arm
    ss = system.component("spot").skillset
    store = build_typestore(ss, typemap)
    m = Manager(ss, store, info="/spot/spot_skillset_manager", clock=lambda: 2**31 + 5.0)
    caplog.set_level("WARNING", logger="skinet.simulator")
    for _ in range(2):
        status = m.status()
        back = to_plain(decode(store, status.typename, encode(store, status.typename, status.msg)))
        assert back["stamp"] == {"sec": 2**31 - 1, "nanosec": 999_999_999}
    assert [r.getMessage() for r in caplog.records if r.name.startswith("skinet.simulator")] == [
        "spot: stamp 2147483653 s is past the int32 seconds of ROS Time (2038-01-19 03:14:07 UTC): clamped to it "
        "(and every later one like it)"]
    assert m.clamped == 2


class Bench:
    """A robot without Zenoh for :class:`~services.simulator.world.World`: starts are told to its hooks as a
    manager tells them, ``terminate`` ends the execution running (False for another one)."""

    def __init__(self, system: Any):
        self.system = system
        self.on_start: list[Any] = []
        self.running: dict[tuple[str, str], str] = {}
        self.lock = threading.Lock()
        self.starts = 0

    def start(self, skillset: str, skill: str) -> str:
        with self.lock:
            self.starts += 1
            id_ = self.running[(skillset, skill)] = f"r{self.starts}"
            for hook in self.on_start:
                hook(skillset, skill, id_)
            return id_

    def terminate(self, skillset: str, skill: str, kind: str, mode: str = "", id_: str | None = None) -> bool:
        with self.lock:
            if self.running.get((skillset, skill)) != id_:
                return False
            del self.running[(skillset, skill)]
            return True


def settle(world: Any) -> None:
    """Until the world has ended every execution it is not holding."""
    deadline = time.monotonic() + 10
    while not world.idle():
        assert time.monotonic() < deadline, world.ends
        time.sleep(0.005)


def run_through(world: Any, bench: Bench, skill: tuple[str, str], times: int) -> None:
    """Start ``skill`` ``times`` times, each after the world ended the one before."""
    for _ in range(times):
        bench.start(*skill)
        settle(world)


def test_the_failure_rate_draws_failures_from_its_seed(spot_arm) -> None:
    """--failure-rate P --seed N: each run fails with probability P, in a failure mode drawn from a generator
    seeded with N, so the same seed gives the same outcomes in the same order of starts."""
    from services.simulator.world import World
    from skinet.pilot.run import Outcomes

    system, _ = spot_arm
    seen = []
    for seed in (3, 3, 4):
        bench = Bench(system)
        world = World(bench, Outcomes(system, failure_rate=0.5, seed=seed), 0.0)
        try:
            run_through(world, bench, ("spot", "init_power"), 12)
        finally:
            world.close()
        seen.append([e.mode for e in world.ends])
        assert all(e.ok for e in world.ends) and world.ended == [f"spot:init_power.{e.kind}.{e.mode}"
                                                                 for e in world.ends]
    assert seen[0] == ["no_battery", "no_battery", "powered_on", "no_battery", "powered_on", "no_battery",
                       "no_battery", "powered_on", "powered_on", "no_battery", "no_battery", "powered_on"]
    assert seen[1] == seen[0] and seen[2] != seen[0]
    for rate, mode in ((0.0, "powered_on"), (1.0, "no_battery")):
        bench = Bench(system)
        world = World(bench, Outcomes(system, failure_rate=rate, seed=3), 0.0)
        try:
            run_through(world, bench, ("spot", "init_power"), 5)
        finally:
            world.close()
        assert world.ended == [f"spot:init_power.{'success' if rate == 0 else 'failure'}.{mode}"] * 5


def test_a_script_comes_before_the_outcomes_and_held_skills_wait_for_release(spot_arm) -> None:
    """The tests' controls: a script of modes per skill (every start still counts as a run of the outcomes: the
    second run's declared failure), a skill held until released, random durations in [0, duration] from the rng."""
    import random

    from services.simulator.world import End, World
    from skinet.pilot.run import Failure, Outcomes

    system, _ = spot_arm

    class Recorded(random.Random):
        spans: list[tuple[float, float]] = []

        def uniform(self, a: float, b: float) -> float:
            self.spans.append((a, b))
            return super().uniform(a, b)

    bench = Bench(system)
    rng = Recorded(1)
    world = World(bench, Outcomes(system, [Failure("spot", "stand_up", 2, "fell")]), 0.01,
                  script={("spot", "stand_up"): ["fell"]}, holding=[("spot", "teleop")], rng=rng)
    try:
        run_through(world, bench, ("spot", "stand_up"), 3)
        assert world.ended == ["spot:stand_up.failure.fell", "spot:stand_up.failure.fell",
                               "spot:stand_up.success.standing"]
        teleop = bench.start("spot", "teleop")
        run_through(world, bench, ("manipulator", "arm_ready"), 1)  # the others go on meanwhile
        assert world.ended[-1] == "manipulator:arm_ready.success.ready"
        assert bench.running == {("spot", "teleop"): teleop}  # held
        world.release("spot", "teleop")
        settle(world)
        assert world.ends[-1] == End("spot", "teleop", teleop, "success", "done", True)
        assert rng.spans == [(0, 0.01)] * 5
    finally:
        world.close()


def test_the_command_line_simulator_serves_a_robot_whose_skills_end_by_themselves(router, client_factory,
                                                                                   spot_arm) -> None:
    """``python -m services.simulator SYSTEM.toml --self-ending`` as a process of its own: an operator's request
    starts spot:init_power, which fails by itself (--failure-rate 1) 0.1 s later; a line for each; SIGTERM
    stops it with status 0."""
    import sys

    from services.common.requests import Requests
    from skinet.ros.requests import skill_request, status_request
    from tests.processes import Watched
    from tests.services.conftest import REPO, client_args

    system, typemap = spot_arm
    sim = Watched([sys.executable, "-m", "services.simulator", "skillsets/spot_arm.toml", "--self-ending",
                   "--skill-duration", "0.1", "--failure-rate", "1", "--seed", "5", "--log-level", "WARNING",
                   *client_args(router)], REPO)
    session = client_factory()
    log = StatusLog(session, system, typemap)
    spot = system.component("spot")
    store = build_typestore(spot.skillset, typemap)
    requests = Requests(session, [(spot, store)])
    try:
        sim.wait_for(lambda text: "Ctrl-C stops" in text, "serving")
        assert sim.lines == ["python -m services.simulator: the skillset managers of spot_arm; each skill ends by "
                             "itself 0.1 s after it starts (failure rate 1, seed 5); Ctrl-C stops"]
        deadline = time.monotonic() + 30
        while not log.items:  # until the manager answers: its subscriptions reached the router
            assert time.monotonic() < deadline, "no status from the simulated manager"
            requests.put("spot", *status_request(store, spot.skillset))
            time.sleep(0.2)
        requests.put("spot", *skill_request(store, spot.skillset, "init_power", "op-1"))
        sim.wait_for(lambda text: "end " in text, "the skill's end")
        assert sim.lines[1:] == ["start spot:init_power op-1", "end   spot:init_power.failure.no_battery op-1"]
        responses = [m for ss, topic, m, _ in log.items if topic.endswith("/response")]
        assert [(m["id"], m["result"], m["name"]) for m in responses] == [("op-1", R["FAILURE"], "no_battery")]
        assert sim.stop() == 0
    finally:
        requests.close()
        sim.stop()


def test_the_simulator_says_what_runs_a_file_it_does_not_play(capsys) -> None:
    """A pilot run file names the commands that play it; a system file needs --self-ending; a scenario refuses
    it."""
    import services.simulator.__main__ as simulator_main

    assert simulator_main.main(["skillsets/missions/pilot.toml"]) == 1
    assert capsys.readouterr().err == (
        "skillsets/missions/pilot.toml:5:1: error: a pilot run, not a scenario or a system file: `skinet demo "
        "skillsets/missions/pilot.toml` plays it; to drive a simulated robot yourself, `skinet run "
        "skillsets/spot_arm.toml --simulate` and `skinet goal` (docs/pilot.md)\n")
    assert simulator_main.main(["skillsets/spot_arm.toml"]) == 1
    assert capsys.readouterr().err == ("skillsets/spot_arm.toml:4:1: error: a system file, not a scenario: add "
                                       "--self-ending to simulate its robot with skills that end by themselves\n")
    with pytest.raises(SystemExit) as exit_:
        simulator_main.main(["skillsets/missions/unassisted.toml", "--self-ending"])
    assert exit_.value.code == 2
    assert capsys.readouterr().err == (
        "python -m services.simulator: error: --self-ending takes a system file; skillsets/missions/unassisted.toml "
        "is a scenario (its steps end the skills) (see python -m services.simulator --help)\n")
