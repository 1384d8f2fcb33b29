"""Access control and authentication of ``docker/zenoh/router.json5`` (docs/semantics.md §7).

The router is the Python wheel in router mode with the shipped configuration (only
the users file path, the listening port and its certificate changed), on a ``tls/``
endpoint with mutual TLS; clients log in with users whose passwords and certificates
the tests make (none is in the repository), each presenting its own certificate.
No containers: real sockets on 127.0.0.1.
"""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from deploy_support import (
    REPO, SYSTEM, UNASSISTED, MissionObserver, Services, Tokens, acl_router_config, expected_violations, free_port,
    load_scenario, login, wait_until,
)
from skinet.wire import keys
from tests.services.test_outage import Outage, run

EVENTS = keys.events(SYSTEM, "spot")
HEARTBEAT = keys.heartbeat(SYSTEM, "bridge_ros2/robot1")
PREDICT = keys.predict(SYSTEM, "monitor")  # the monitor asks under its login (issue 14)
ROS_STATUS = "spot/spot_skillset_manager/spot_skillset/status"
STATUS_REQUEST = "spot/spot_skillset_manager/spot_skillset/status_request"
USERS = ("bridge", "monitor", "predictor", "robot", "observer")


@pytest.fixture(scope="module")
def acl_router() -> Iterator[str]:
    """The shipped router configuration on a free loopback TLS port; yields the endpoint."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = zenoh.open(acl_router_config(endpoint))
    try:
        yield endpoint
    finally:
        router.close()


@pytest.fixture(scope="module")
def sessions(acl_router: str) -> Iterator[dict[str, zenoh.Session]]:
    """One logged-in client per user, ``reader``, an observer that only listens, and ``asker``,
    a monitor that only queries.

    A session delivers its own publications to its own subscribers without the
    router, so what the router lets through is seen from a session of its own.
    """
    opened = {user: login(acl_router, user) for user in USERS}
    opened["reader"] = login(acl_router, "observer")
    opened["asker"] = login(acl_router, "monitor")  # a monitor that declares nothing itself
    try:
        yield opened
    finally:
        for s in opened.values():
            s.close()


class Inbox:
    """Payloads received by a subscriber, with a wait for one of them."""

    def __init__(self, session: zenoh.Session, key_expr: str):
        self.payloads: list[tuple[str, str]] = []
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(key_expr, self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.payloads.append((str(sample.key_expr), sample.payload.to_string()))
            self._cond.notify_all()

    def wait_for(self, payload: str, timeout: float = 5.0) -> None:
        with self._cond:
            assert self._cond.wait_for(lambda: any(p == payload for _, p in self.payloads), timeout), \
                f"'{payload}' never arrived; got {self.payloads}"

    def received(self) -> set[str]:
        with self._cond:
            return {p for _, p in self.payloads}

    def close(self) -> None:
        self._sub.undeclare()


def test_only_the_bridge_user_publishes_canonical_events(sessions: dict[str, zenoh.Session]) -> None:
    events = Inbox(sessions["reader"], keys.events(SYSTEM, "*"))
    everything = Inbox(sessions["reader"], "**")
    try:
        time.sleep(0.3)  # let the subscriptions reach the router
        for user in USERS:
            if user != "bridge":
                sessions[user].put(EVENTS, f"stranger {user}")
        # Wildcard publications are included in no allow rule either.
        sessions["robot"].put("**", "robot on **")
        sessions["robot"].put(keys.events("*", "spot"), "robot on skinet/*/events/spot")
        sessions["monitor"].put(keys.events("*", "*"), "monitor on skinet/*/events/*")
        sessions["bridge"].put(EVENTS, "bridge")
        events.wait_for("bridge")
        time.sleep(0.3)  # anything wrongly let through would have arrived by now
        assert events.received() == {"bridge"}
        assert everything.received() == {"bridge"}
    finally:
        events.close()
        everything.close()


def test_each_user_publishes_only_its_own_keys(sessions: dict[str, zenoh.Session]) -> None:
    allowed = {
        "bridge": {EVENTS, HEARTBEAT, STATUS_REQUEST},
        "monitor": {keys.state(SYSTEM), keys.verdicts(SYSTEM), keys.unsafe(SYSTEM), keys.state_space(SYSTEM),
                    keys.divergences(SYSTEM)},
        "predictor": set(),
        "robot": {ROS_STATUS, STATUS_REQUEST},
        "observer": set(),
    }
    tried = set().union(*allowed.values()) | {keys.model(SYSTEM, "d1"), PREDICT, "elsewhere/key"}
    inbox = Inbox(sessions["reader"], "**")
    try:
        time.sleep(0.3)
        for user in USERS:
            for key in sorted(tried):
                sessions[user].put(key, f"{user} {key}")
        sessions["bridge"].put(EVENTS, "marker")
        inbox.wait_for("marker")
        time.sleep(0.3)
        got = inbox.received() - {"marker"}
        assert got == {f"{user} {key}" for user, ks in allowed.items() for key in ks}
    finally:
        inbox.close()


def _replies(session: zenoh.Session, key: str = PREDICT) -> list[str]:
    return sorted(r.ok.payload.to_string() if r.ok is not None else f"error {r.err.payload.to_string()}"
                  for r in session.get(key, target=zenoh.QueryTarget.ALL,
                                       consolidation=zenoh.ConsolidationMode.NONE, timeout=2.0))


@pytest.mark.parametrize("declared, queried", [
    (keys.predict("*", "*"), PREDICT),  # the shared key
    (keys.predict_instance("*", "*", "p1"), keys.predict_instance(SYSTEM, "monitor", "p1")),  # an instance's own key
])
def test_only_predictors_answer_prediction_queries(sessions: dict[str, zenoh.Session], declared: str,
                                                   queried: str) -> None:
    def answer(text: str):
        def on_query(query: zenoh.Query) -> None:
            with query:
                query.reply(queried, text)
        return on_query

    impostors = [sessions[user].declare_queryable(declared, answer(f"impostor {user}"), complete=True)
                 for user in USERS if user != "predictor"]
    impostors.append(sessions["robot"].declare_queryable("**", answer("robot on **"), complete=True))
    try:
        time.sleep(0.3)
        # Impostors alone: their declarations never reached the router, so nothing answers
        # (and nothing holds the query until its timeout).
        t0 = time.monotonic()
        assert _replies(sessions["asker"], queried) == []
        assert time.monotonic() - t0 < 1.0
        genuine = sessions["predictor"].declare_queryable(declared, answer("predictor"), complete=True)
        try:
            time.sleep(0.3)
            assert _replies(sessions["asker"], queried) == ["predictor"]
            # Observers may not ask: not the predictor (under any name), not the models, not `**`.
            assert _replies(sessions["reader"], queried) == []
            assert _replies(sessions["reader"], queried.replace("/monitor", "/observer")) == []
            assert [r for r in sessions["reader"].get("**", timeout=1.0) if r.ok is not None] == []
        finally:
            genuine.undeclare()
    finally:
        for q in impostors:
            q.undeclare()


@pytest.mark.parametrize("user, password, certificate", [
    (None, None, None), ("observer", "not-the-password", None), ("nobody", "x", None),
    (None, None, "bridge"),  # a certificate stolen alone
    ("bridge", "not-the-password", "bridge"),
])
def test_sessions_without_valid_credentials_are_refused(acl_router: str, user: str | None, password: str | None,
                                                        certificate: str | None) -> None:
    with pytest.raises(zenoh.ZError):
        login(acl_router, user, password, certificate)


# A password and a certificate of two different users (each valid alone): the router's
# subjects pair each user's name with its certificate's common name, so these match none.
MISMATCHED = [("bridge", "observer"),  # the bridge's password with the dashboard's certificate
              ("observer", "bridge"),  # the observer's own login with a certificate stolen from the bridge
              ("monitor", "predictor")]


@pytest.mark.parametrize("user, certificate", MISMATCHED)
def test_a_certificate_with_another_users_password_is_refused_everything(
        acl_router: str, sessions: dict[str, zenoh.Session], user: str, certificate: str) -> None:
    impostor = login(acl_router, user, certificate=certificate)  # the TLS and login steps pass
    events = Inbox(sessions["reader"], keys.events(SYSTEM, "*"))
    seen = Inbox(impostor, "**")
    token = impostor.liveliness().declare_token(f"skinet/{SYSTEM}/alive/bridge_ros2/impostor")
    answering = impostor.declare_queryable(keys.predict(SYSTEM, "*"), lambda q: q.reply(q.key_expr, "impostor"),
                                           complete=True)
    checks = sessions["monitor"].declare_queryable(keys.check(SYSTEM, "*"), lambda q: q.reply(q.key_expr, "monitor"),
                                                   complete=True)
    try:
        time.sleep(0.3)
        own = f"impostor {user} with {certificate}'s certificate"
        impostor.put(EVENTS, own)
        sessions["bridge"].put(EVENTS, "bridge")  # what the impostor's subscription would receive
        events.wait_for("bridge")
        time.sleep(0.3)
        assert events.received() == {"bridge"}
        assert seen.received() == {own}  # its own publication only, delivered inside its session
        assert _replies(sessions[user], keys.check(SYSTEM, user)) == ["monitor"]  # the user's own session asks
        assert _replies(impostor, keys.check(SYSTEM, user)) == []
        assert [str(r.ok.key_expr) for r in sessions["reader"].liveliness().get("skinet/**/impostor", timeout=1.0)
                if r.ok is not None] == []
        assert _replies(sessions["asker"]) == []  # its prediction queryable never reached the router
    finally:
        checks.undeclare()
        answering.undeclare()
        token.undeclare()
        seen.close()
        events.close()
        impostor.close()


def test_a_link_without_a_certificate_is_refused_everything() -> None:
    """The shipped subjects on a tcp/ endpoint (which it does not serve): a correct password
    alone matches no subject, since no certificate names its user."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(acl_router_config(endpoint, tcp_twins=False))
    bridge, reader = login(endpoint, "bridge"), login(endpoint, "observer")
    inbox = Inbox(reader, "**")
    try:
        time.sleep(0.3)
        bridge.put(EVENTS, "bridge over tcp")
        time.sleep(0.5)
        assert inbox.received() == set()
    finally:
        inbox.close()
        for s in (bridge, reader, router):
            s.close()


def test_the_services_run_the_mission_through_the_acl_router(acl_router: str, tmp_path: Path) -> None:
    """Each service logs in as its user; the unassisted mission gives the replay's violations."""
    observer_session = login(acl_router, "observer")
    observer = MissionObserver(observer_session)
    tokens = Tokens(observer_session)
    services = Services(tmp_path)

    def start(module: str, user: str, *args: str) -> subprocess.Popen:
        return services.start(module, user, acl_router, *args)

    try:
        start("services.predictor", "predictor")
        start("services.monitor", "monitor", "skillsets/spot_arm.toml")
        start("services.bridge_ros2", "bridge", "skillsets/spot_arm.toml")
        wait_until(lambda: all(tokens.of(s) for s in ("predictor", "monitor", "bridge_ros2")), 30,
                   f"the services' liveliness tokens (got {sorted(tokens.alive)})")
        sim = start("services.simulator", "robot", str(UNASSISTED.relative_to(REPO)), "--speed", "20")
        assert sim.wait(timeout=60) == 0
        wait_until(lambda: observer.quiet_for(1.0), 20, "the monitor to settle")
        assert observer.violations(load_scenario()) == expected_violations()
        # The predictor answered through the ACL: fresh reports were published.
        assert any(not report.prediction_stale for _, report in observer.unsafe)
    finally:
        tokens.close()
        observer.close()
        services.close()
        observer_session.close()


def test_events_survive_a_router_restart_through_the_acl() -> None:
    """The shipped ACL lets zenoh.ext's recovery through (its `@adv` keys, the cache's replies)."""
    outage = Outage(lambda endpoint: zenoh.open(acl_router_config(endpoint)), login)
    try:
        counters, _ = run(outage, cache=4096, seconds=3.0)
    finally:
        outage.close()
    assert (counters.received, counters.applied, counters.lost, counters.unrecovered, counters.out_of_order,
            counters.duplicates) == (200, 200, 0, 0, 0, 0)
