"""The pilot's and the operators' rights in ``docker/zenoh/router.json5`` (issue 24 item 2; docs/semantics.md §7, §8).

The router is the Python wheel with the shipped configuration on a ``tls/`` endpoint
(mutual TLS, each user with its own password and certificate, as in ``test_acl.py``);
the robot is the simulator's managers (the real request protocol, CDR on the keys of
both gateways) logged in as ``robot``, or examples/nav2's simulated action servers.  The
pilot login may drive the managers' skills and the bound actions (with the pilot's own
actuators) and publish its own keys, never report for the robot or the bridge; only the
``operator`` login reaches the real pilot's goal queryable; and the services, each a
process with its own login, drive an operator's goal to ``reached`` through the router.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from deploy_support import REPO, SYSTEM, Services, Tokens, acl_router_config, free_port, login, wait_until
from services.pilot import start_pilot
from services.pilot.errors import ActError
from services.pilot.act import ManagerActuator
from services.pilot.bound_act import BoundActuator
from services.simulator.bound import BoundSimulator
from services.simulator.driver import Operator
from services.simulator.service import Simulator
from skinet.system.load import load_bindings, load_system, load_typemap
from skinet.ros.interfaces import status_request_topic
from skinet.ros.requests import event_request, skill_interrupt, skill_request
from skinet.ros.keys import KeyStyle, manager_topics
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import PilotCommand, PilotGoalReply, PilotGoalRequest, PilotStatus
from test_acl import Inbox, acl_router  # noqa: F401 (the shipped configuration's router)

SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
NAV2_FILE = REPO / "examples" / "nav2" / "nav2.toml"
# What a deployment of examples/nav2 adds to the rules "robot traffic" (its robot's own keys) and "deliver"
# (the last action status kept by the gateway's cache, which `**` does not reach: docs/deployment.md).
NAV2_ROBOT = ["navigate_to_pose/**", "dock_robot/**", "undock_robot/**", "bt_navigator/**", "battery_state",
              "emergency_stop"]
NAV2_CACHES = [k for a in ("navigate_to_pose", "dock_robot", "undock_robot")
               for k in (f"{a}/_action/status/@adv/**", f"*/{a}/_action/status/*/*/@adv/**")]
LOGINS = ("pilot", "operator", "observer", "robot", "bridge", "monitor")
STYLES = {"zenoh-bridge-ros2dds": KeyStyle(), "its namespace": KeyStyle(namespace="robot1"),
          "rmw_zenoh": KeyStyle(rmw_zenoh=True, domain=3)}
STYLE_FLAGS = {"zenoh-bridge-ros2dds": (), "its namespace": ("--namespace", "robot1"),
               "rmw_zenoh": ("--rmw-zenoh", "--domain", "3")}  # the same, for the bridge and the pilot


@pytest.fixture(scope="module")
def sessions(acl_router: str) -> Iterator[dict[str, zenoh.Session]]:
    """One client per login, and ``reader``, an observer that only listens (a session delivers its
    own publications to itself without the router: what the router lets through is seen elsewhere)."""
    opened = {user: login(acl_router, user) for user in LOGINS}
    opened["reader"] = login(acl_router, "observer")
    try:
        yield opened
    finally:
        for s in opened.values():
            s.close()


def robot(sessions: dict[str, zenoh.Session], style: KeyStyle) -> Simulator:
    system, _ = load_system(SYSTEM_FILE)
    return Simulator(sessions["robot"], system, load_typemap(SYSTEM_FILE), style=style)


@pytest.mark.parametrize("style", STYLES.values(), ids=STYLES.keys())
def test_the_pilot_login_drives_the_managers_skills(sessions: dict[str, zenoh.Session], style: KeyStyle) -> None:
    """The pilot's actuator starts a skill and interrupts it (asking the manager's status first, for the
    running id) through the router; the same requests from the operator and observer logins (who set
    goals or watch) do not reach the manager, nor an event request from the pilot (events are the robot's)."""
    sim = robot(sessions, style)
    system, spot, store = sim.system, sim.nodes["spot"].component.skillset, sim.nodes["spot"].store
    others = [Operator(sessions[u], sim) for u in ("operator", "observer")]
    pilot_gui = Operator(sessions["pilot"], sim)
    actuators: list[ManagerActuator] = []

    def actuator() -> ManagerActuator:
        actuators.append(ManagerActuator(sessions["pilot"], system, load_typemap(SYSTEM_FILE), style, "p1"))
        return actuators[-1]

    try:
        time.sleep(0.3)  # the managers' subscriptions reach the router
        for other in others:
            assert not other.send("spot", skill_request(store, spot, "init_power", "stranger"), timeout=0.5)
        assert sim.skill_status("spot", "init_power") == (False, "")
        actuator().send(PilotCommand(skillset="spot", transition="init_power.start"))
        wait_until(lambda: sim.skill_status("spot", "init_power") == (True, "p1-1"), 5, "the pilot's start")
        for other in others:
            assert not other.send("spot", skill_interrupt(store, spot, "init_power", "p1-1"), timeout=0.5)
        assert sim.skill_status("spot", "init_power") == (True, "p1-1")
        asked = sim.handled("spot", status_request_topic(spot))
        actuator().send(PilotCommand(skillset="spot", transition="init_power.interrupt"))  # it has seen no status
        assert sim.handled("spot", status_request_topic(spot)) == asked + 1
        wait_until(lambda: sim.skill_status("spot", "init_power") == (False, "p1-1"), 5, "the pilot's interrupt")
        assert not pilot_gui.send("spot", event_request(store, spot, "e", "power_switchoff"), timeout=0.5)
    finally:
        for o in (*actuators, pilot_gui, *others):
            o.close()
        sim.close()


def test_the_pilot_login_cannot_speak_for_the_robot_the_bridge_or_the_monitor(
        sessions: dict[str, zenoh.Session]) -> None:
    """Canonical events, heartbeats, the managers' statuses, responses and event requests (both
    gateways' keys), the monitor's results: nothing the pilot puts there leaves the router; its status,
    the skills' requests and interrupts and the managers' status requests do."""
    system, _ = load_system(SYSTEM_FILE)
    allowed, refused = {keys.pilot_status(SYSTEM)}, {
        keys.events(SYSTEM, "spot"), keys.heartbeat(SYSTEM, "bridge_ros2/robot1"), keys.state(SYSTEM),
        keys.verdicts(SYSTEM), keys.unsafe(SYSTEM), keys.divergences(SYSTEM), keys.pilot_goal(SYSTEM, "operator"),
        keys.check(SYSTEM, "pilot"), keys.model(SYSTEM, "d1"), "**", "spot/**", "skinet/**", "elsewhere/key"}
    for comp in system.components:
        for style in STYLES.values():
            for topic in manager_topics(comp.skillset):
                key = style.key(comp.manager, topic).replace("*", "RIHS01_0")  # rmw_zenoh: any type hash
                (allowed if topic.kind in ("skill_request", "skill_interrupt", "status_request") else refused).add(key)
    inbox = Inbox(sessions["reader"], "**")
    try:
        time.sleep(0.3)
        for key in sorted(allowed | refused):
            sessions["pilot"].put(key, f"pilot {key}")
        sessions["pilot"].put(keys.pilot_status(SYSTEM), "marker")
        inbox.wait_for("marker")
        time.sleep(0.3)  # anything wrongly let through would have arrived by now
        assert inbox.received() - {"marker"} == {f"pilot {key}" for key in allowed}
        assert len(allowed) == 1 + 3 * sum(2 * len(c.skillset.skills) + 1 for c in system.components)
    finally:
        inbox.close()


def test_the_pilot_token_is_its_own(sessions: dict[str, zenoh.Session]) -> None:
    """The pilot announces itself under alive/pilot and may not pose as the monitor or the bridge."""
    tokens = [sessions["pilot"].liveliness().declare_token(keys.alive(SYSTEM, service, "p1"))
              for service in ("pilot", "monitor", "bridge_ros2")]
    try:
        time.sleep(0.5)
        seen = sorted(str(r.ok.key_expr) for r in sessions["reader"].liveliness().get(keys.alive(SYSTEM, "*", "p1"),
                                                                                        timeout=1.0) if r.ok)
        assert seen == [keys.alive(SYSTEM, "pilot", "p1")]
    finally:
        for t in tokens:
            t.undeclare()


def test_only_the_pilot_login_answers_goals_and_only_operators_ask(acl_router: str,
                                                                  sessions: dict[str, zenoh.Session]) -> None:
    """The real pilot, logged in as ``pilot``: only the operator login, under its own name, gets its
    answers (a goal, a cancel); the other logins' goals and cancels stop at the router, and impostors
    of the other logins cannot serve the goal key or the status.  Everybody reads the pilot's status."""
    def answer(text: str):
        def on_query(query: zenoh.Query) -> None:
            with query:
                query.reply(query.key_expr, text)
        return on_query

    servers = {u: login(acl_router, u) for u in LOGINS}  # a session would answer its own queries itself
    impostors = [q for u in LOGINS if u != "pilot"
                 for q in (servers[u].declare_queryable(keys.pilot_goal("*", "*"), answer(f"impostor {u}")),
                           servers[u].declare_queryable(keys.pilot_status("*"), answer(f"impostor {u}")))]
    system, _ = load_system(SYSTEM_FILE)
    goal = PilotGoalRequest(system=SYSTEM, goals=["run spot:init_power"])
    cancel = PilotGoalRequest(system=SYSTEM, op="cancel")

    def ask(user: str, request: PilotGoalRequest, client: str | None = None) -> list[str]:
        return _replies(sessions[user], keys.pilot_goal(SYSTEM, client or user), encode(request))

    try:
        time.sleep(0.3)
        assert ask("operator", goal) == []  # no impostor answers
        pilot = start_pilot(servers["pilot"], system, instance="p1", client="pilot",
                            typemap=load_typemap(SYSTEM_FILE), memory_limit=None)  # see tests/services/pilot_robot.py
        try:
            wait_until(lambda: _replies(sessions["reader"], keys.pilot_status(SYSTEM)) != [], 5, "the pilot's status")
            for user in ("observer", "reader", "robot", "bridge", "monitor", "pilot"):
                assert ask(user, goal) == [] and ask(user, goal, "operator") == [], user
            for key in (keys.pilot_goal(SYSTEM, "observer"), keys.pilot_goal(SYSTEM, "*"),
                        f"skinet/{SYSTEM}/pilot/**", f"skinet/{SYSTEM}/**"):
                assert _replies(sessions["operator"], key, encode(goal)) == [], key
            (reply,) = ask("operator", goal)
            assert decode(reply, PilotGoalReply).model_dump(include={"accepted", "reason", "goal_id"}) == {
                "accepted": True, "reason": "", "goal_id": 1}
            (status,) = _replies(sessions["reader"], keys.pilot_status(SYSTEM))
            got = decode(status, PilotStatus)
            assert (got.pilot, got.goal_id, got.client, got.commands) == ("p1", 1, "operator", 0)
            assert ask("observer", cancel) == [] and ask("observer", cancel, "operator") == []
            (reply,) = ask("operator", cancel)
            assert decode(reply, PilotGoalReply).accepted
            wait_until(lambda: pilot.status.state == "cancelled", 5, "the goal cancelled")
            assert pilot.status.reason == "cancelled by operator"
        finally:
            pilot.close()
    finally:
        for q in impostors:
            q.undeclare()
        for s in servers.values():
            s.close()


def _replies(session: zenoh.Session, key: str, payload: bytes | None = None) -> list[bytes]:
    return [r.ok.payload.to_bytes() for r in session.get(key, payload=payload, target=zenoh.QueryTarget.ALL,
                                                         consolidation=zenoh.ConsolidationMode.NONE, timeout=2.0)
            if r.ok is not None]


@pytest.fixture(scope="module")
def nav2_router() -> Iterator[str]:
    """The shipped configuration with examples/nav2's robot keys, as its deployment has them."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    config = acl_router_config(endpoint)
    acl = json.loads(config.get_json("access_control"))
    rules = {r["id"]: r for r in acl["rules"]}
    rules["robot traffic"]["key_exprs"] += [*NAV2_ROBOT, *(f"*/{k}" for k in NAV2_ROBOT), *NAV2_CACHES]
    rules["deliver"]["key_exprs"] += NAV2_CACHES
    config.insert_json5("access_control", json.dumps(acl))
    router = zenoh.open(config)
    try:
        yield endpoint
    finally:
        router.close()


@pytest.mark.parametrize("style", [KeyStyle(), KeyStyle(rmw_zenoh=True)], ids=["zenoh-bridge-ros2dds", "rmw_zenoh"])
def test_the_pilot_login_sends_and_cancels_bound_action_goals(nav2_router: str, style: KeyStyle) -> None:
    """Skills bound to actions (docs/semantics.md §9): the pilot's actuator sends a goal to the robot's action server
    and cancels it (after reading the action's last status); the same actuator logged in as the
    operator or the observer gets no answer, so nothing starts or stops."""
    system, _ = load_system(NAV2_FILE)
    bindings, _ = load_bindings(system)
    robot_session = login(nav2_router, "robot")
    sim = BoundSimulator(robot_session, system, bindings, style=style)
    clients = {u: login(nav2_router, u) for u in ("pilot", "operator", "observer")}
    actuators = {u: BoundActuator(s, bindings, style=style, timeout=1.0) for u, s in clients.items()}
    server = sim.actions[("nav2", "navigate")]
    start, interrupt = (PilotCommand(skillset="nav2", transition=f"navigate.{k}") for k in ("start", "interrupt"))
    try:
        time.sleep(0.3)
        for user in ("operator", "observer"):
            with pytest.raises(ActError, match="no reply from the action server of /navigate_to_pose"):
                actuators[user].send(start)
        assert server.logic.current() is None
        assert actuators["pilot"].send(start).endswith(": accepted")
        goal = server.logic.current()
        assert goal is not None and goal.id == actuators["pilot"].sent[("nav2", "navigate")].id
        for user in ("operator", "observer"):
            with pytest.raises(ActError):  # it reads no status, or gets no answer to its cancel
                actuators[user].send(interrupt)
        assert server.logic.current() is goal
        assert actuators["pilot"].send(interrupt).endswith("(the goal the pilot sent): canceling")
        assert server.logic.current() is None
        # A goal the operator's own client sent (on the robot's side): the pilot finds it in the action's
        # last status, read from the gateway's cache through the router, and cancels it.
        assert sim.send_goal("nav2", "navigate")
        theirs = server.logic.current()
        assert theirs is not None
        # Its status reaches the gateway's cache a moment after the accept: until then there is nothing to cancel.
        deadline = time.monotonic() + 10
        while True:
            try:
                sent = actuators["pilot"].send(interrupt)
                break
            except ActError as exc:
                if "is active (its status shows no goal)" not in str(exc) or time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        assert sent.endswith("(the goal the bridge follows): canceling")
        assert server.logic.current() is None
    finally:
        sim.close()
        for s in (*clients.values(), robot_session):
            s.close()


@pytest.mark.parametrize("style", STYLES.keys())
def test_an_operators_goal_is_driven_through_the_acl_router(acl_router: str, tmp_path: Path, style: str) -> None:
    """The services as processes, each with its own login (``python -m services.pilot`` as ``pilot``), the
    managers logged in as ``robot`` behind either gateway (the bridge and the pilot given the same key
    flags): an operator's goal in drive mode is accepted, the pilot's request starts the skill on the
    robot, and its outcome ends the goal reached with one command, none denied."""
    system, _ = load_system(SYSTEM_FILE)
    robot_session, operator, reader = (login(acl_router, u) for u in ("robot", "operator", "observer"))
    sim = Simulator(robot_session, system, load_typemap(SYSTEM_FILE), style=STYLES[style])
    flags = STYLE_FLAGS[style]
    tokens, services = Tokens(reader), Services(tmp_path)
    try:
        services.start("services.predictor", "predictor", acl_router)
        services.start("services.monitor", "monitor", acl_router, "skillsets/spot_arm.toml")
        services.start("services.bridge_ros2", "bridge", acl_router, "skillsets/spot_arm.toml", *flags)
        services.start("services.pilot", "pilot", acl_router, "skillsets/spot_arm.toml", "--instance", "p1", *flags)
        wait_until(lambda: all(tokens.of(s) for s in ("predictor", "monitor", "bridge_ros2", "pilot")), 30,
                   f"the services' liveliness tokens (got {sorted(tokens.alive)})")
        request = PilotGoalRequest(system=SYSTEM, goals=["run spot:init_power"], mode="drive")
        (reply,) = [decode(r, PilotGoalReply) for r in _replies(operator, keys.pilot_goal(SYSTEM, "operator"),
                                                                 encode(request))]
        assert (reply.accepted, reply.reason, reply.goal_id) == (True, "", 1), reply
        wait_until(lambda: sim.skill_status("spot", "init_power")[0], 30, "the pilot's request on the robot")
        assert sim.skill_status("spot", "init_power") == (True, "pilot-p1-1")  # the pilot's own execution id
        assert sim.terminate("spot", "init_power", "success", "powered_on")

        def status() -> PilotStatus:
            (payload,) = _replies(reader, keys.pilot_status(SYSTEM))
            return decode(payload, PilotStatus)

        wait_until(lambda: status().state == "reached", 20, "the goal reached")
        last = status()
        assert (last.pilot, last.goal_id, last.client, last.mode, last.commands, last.denied) == (
            "p1", 1, "operator", "drive", 1, 0)
    finally:
        tokens.close()
        services.close()
        sim.close()
        for s in (robot_session, operator, reader):
            s.close()
