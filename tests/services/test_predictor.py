"""The predictor service over real Zenoh on loopback (docs/semantics.md §1, §6, §7).

Predictor processes are clients of a Python router; the test plays the monitor: it
serves the model bundle on ``skinet/<system>/model/<digest>`` and queries
``skinet/<system>/predict/local``.  Expected answers are computed in-process with the
same core functions.
"""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import msgpack
import pytest
import zenoh

from services.common.zenoh_config import session_config
from services.monitor import start_monitor
from services.predictor import start_predictor
from skinet.system.load import load_system
from skinet.system.model import System
from skinet.verify.predict import forecast
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.convert import bundle, marking_of, risks, statuses, system_from_bundle
from skinet.wire.messages import ModelBundle, PredictReply, PredictRequest, SkillsetStatus
from tests.services.conftest import LivelinessWatch

REPO = Path(__file__).resolve().parents[2]
SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
PREDICTOR = "services.predictor"
# Arm moving (mutex Busy): starting Spot breaks action_guard in one step, so risks are non-empty.
ARM_READY = {"manipulator": SkillsetStatus(resources={"mutex": "Busy", "arm_status": "Away"}, running=["arm_ready"])}
QUERY_TIMEOUT = 3.0

Answer = PredictReply | str  # a decoded reply, or "error: ..." for a Zenoh error reply


@pytest.fixture(scope="module")
def system() -> System:
    return load_system(SYSTEM_FILE)[0]


@pytest.fixture(scope="module")
def model(system: System) -> ModelBundle:
    return bundle(system)


class ModelServer:
    """The monitor's model queryable; ``frozen`` ones keep queries without answering."""

    def __init__(self, session: zenoh.Session, b: ModelBundle, digest: str | None = None, frozen: bool = False):
        self.queries = 0
        self.held: list[zenoh.Query] = []
        self._payload, self._frozen = encode(b), frozen
        self._queryable = session.declare_queryable(keys.model(b.system, digest or b.digest), self._on_query)

    def _on_query(self, query: zenoh.Query) -> None:
        self.queries += 1
        if self._frozen:
            self.held.append(query)
            return
        with query:
            query.reply(str(query.key_expr), self._payload)

    def close(self) -> None:
        self._queryable.undeclare()
        for query in self.held:
            query.drop()


def request(system: System, digest: str, skillsets: dict | None = None, seq: int = 1) -> PredictRequest:
    live = skillsets if skillsets is not None else statuses(system, system.initial_marking())
    return PredictRequest(system=system.name, digest=digest, seq=seq, skillsets=live, budget=5.0)


def ask(session: zenoh.Session, payload: bytes | None, system: str = "spot_arm",
        timeout: float = QUERY_TIMEOUT, client: str = keys.LOCAL_CLIENT) -> tuple[list[Answer], float]:
    """Every answer to one predict query (as ``client``), and the seconds the ``get`` took."""
    start = time.monotonic()
    answers: list[Answer] = []
    for reply in session.get(keys.predict(system, client), payload=payload, timeout=timeout):
        if reply.ok is not None:
            answers.append(decode(reply.ok.payload.to_bytes(), PredictReply))
        else:
            answers.append(f"error: {reply.err.payload.to_string()}")
    return answers, time.monotonic() - start


def ask_one(session: zenoh.Session, payload: bytes | None, **kw: object) -> PredictReply:
    answers, _ = ask(session, payload, **kw)  # type: ignore[arg-type]
    assert len(answers) == 1 and isinstance(answers[0], PredictReply), answers
    return answers[0]


def token(instance: str) -> str:
    return keys.alive(keys.ANY_SYSTEM, "predictor", instance)


class Launcher:
    """Starts ``python -m services.predictor --instance ID`` and waits for its token."""

    def __init__(self, spawn: Callable[..., subprocess.Popen], zenoh_args: list[str], alive: LivelinessWatch):
        self.spawn, self.zenoh_args, self.alive = spawn, zenoh_args, alive

    def __call__(self, instance: str, *extra: str) -> subprocess.Popen:
        proc = self.spawn(PREDICTOR, "--instance", instance, "--fetch-timeout", "1", *extra, *self.zenoh_args)
        self.alive.wait_for(token(instance), timeout=15)
        return proc


@pytest.fixture
def predictor(spawn: Callable[..., subprocess.Popen], zenoh_args: list[str], client: zenoh.Session,
              watch: Callable[[zenoh.Session, str], LivelinessWatch]) -> Launcher:
    return Launcher(spawn, zenoh_args, watch(client, token("*")))


# -- (a) answers match the core ----------------------------------------------------------


def test_answers_match_forecast_and_risks(client: zenoh.Session, predictor: Launcher, system: System,
                                          model: ModelBundle) -> None:
    server = ModelServer(client, model)
    proc = predictor("p1")
    for seq, live in enumerate((statuses(system, system.initial_marking()), ARM_READY), 1):
        reply = ask_one(client, encode(request(system, model.digest, live, seq)))
        marking = marking_of(system, live)
        fc = forecast(system, marking, budget=5.0)
        assert (reply.ok, reply.error, reply.seq, reply.digest, reply.instance) == (True, "", seq, model.digest, "p1")
        assert reply.report is not None
        assert (reply.report.markings, reply.report.edges, reply.report.depth, reply.report.timeout_reached) == (
            fc.space.markings, fc.space.edges, fc.space.expanded_depth, False)
        assert reply.risks == risks(system, marking, fc)
    assert reply.risks, "the arm-ready marking has one-step risks"
    assert server.queries == 1, "the model is fetched once, then cached"
    # SIGINT: clean exit, token withdrawn
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=10) == 0
    predictor.alive.wait_gone(token("p1"), timeout=5)


# -- (b) bad requests get ok=False, the service keeps answering ----------------------------


def test_bad_requests_are_answered_with_errors(client: zenoh.Session, predictor: Launcher, system: System,
                                               model: ModelBundle) -> None:
    ModelServer(client, model)
    predictor("p1")
    good = request(system, model.digest).model_dump(mode="json")
    unknown = {"nope": SkillsetStatus()}
    names = ", ".join(c.name for c in system.components)
    cases: list[tuple[bytes | None, str]] = [
        (b"garbage", "not msgpack: unpack(b) received extra data."),
        (None, "empty payload"),
        (msgpack.packb([1, 2]), "expected a map, got list"),
        (msgpack.packb({**good, "v": 2}), "unsupported schema version 2 (expected 1)"),
        (msgpack.packb({k: v for k, v in good.items() if k != "seq"}), "invalid PredictRequest: seq: Field required"),
        (encode(request(system, model.digest, unknown, seq=9)),
         f"request: error: unknown skillset 'nope' (skillsets: {names})"),
        (encode(request(system, model.digest).model_copy(update={"system": "other"})),
         "system 'other' does not match key 'skinet/spot_arm/predict/local'"),
        (encode(request(system, "not/a/digest")),
         "digest 'not/a/digest' cannot be used in a Zenoh key (letters, digits, _ - . only)"),
    ]
    for payload, error in cases:
        reply = ask_one(client, payload)
        assert (reply.ok, reply.error, reply.instance) == (False, error, "p1")
        assert reply.system == "spot_arm"
        assert ask_one(client, encode(request(system, model.digest))).ok, f"no answer after {error!r}"
    assert ask_one(client, encode(request(system, model.digest, unknown, seq=9))).seq == 9


# -- (c) two instances: one answer per query, failover on SIGKILL, restart, SIGTERM --------


def test_failover_between_two_instances(client: zenoh.Session, predictor: Launcher, system: System,
                                        model: ModelBundle) -> None:
    ModelServer(client, model)
    # One client asking as fast as it can: no per-client limit here (see test_rate_limit_per_client).
    procs = {name: predictor(name, "--rate-limit", "0") for name in ("pa", "pb")}
    payload = encode(request(system, model.digest))
    first = [ask_one(client, payload).instance for _ in range(10)]
    assert len(set(first)) == 1, f"default target: one instance answers ({first})"
    active = first[0]
    standby = "pb" if active == "pa" else "pa"

    results: list[tuple[list[Answer], float]] = []
    stop = threading.Event()

    def flow() -> None:
        while not stop.is_set():
            results.append(ask(client, payload))

    thread = threading.Thread(target=flow)
    thread.start()
    try:
        deadline = time.monotonic() + 5
        while len(results) < 20 and time.monotonic() < deadline:
            time.sleep(0.01)
        procs[active].kill()
        killed_at = len(results)
        predictor.alive.wait_gone(token(active), timeout=5)
        deadline = time.monotonic() + 5
        while sum(1 for a, _ in results[killed_at:] if _instances(a) == [standby]) < 20 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        stop.set()
        thread.join()
    assert all(took < QUERY_TIMEOUT + 0.5 for _, took in results), "no query outlives its timeout"
    answered = [_instances(a) for a, _ in results]
    # A query in flight at the kill returns at once without a reply, or (rarely, when
    # the router had already forwarded it) with Zenoh's error reply at its timeout.
    lost = [(i, a) for i, a in enumerate(answered) if a in ([], ["error: Timeout"])]
    assert len(lost) <= 2 and all(i >= killed_at for i, _ in lost), f"only queries in flight at the kill: {lost}"
    assert all(a == [active] for a in answered[:killed_at]), answered[:killed_at]
    assert all(a in ([active], [standby]) for i, a in enumerate(answered) if i not in dict(lost)), answered
    assert answered[-20:] == [[standby]] * 20, "the standby takes over"
    assert all(a[0].ok for a, _ in results if a and isinstance(a[0], PredictReply))

    predictor(active)  # restarted: answers continue, still one per query
    again = [ask_one(client, payload) for _ in range(10)]
    assert all(r.ok for r in again)
    assert len({r.instance for r in again}) == 1
    # SIGTERM retires the answering instance cleanly; the other one takes over
    serving = again[0].instance
    procs[serving].send_signal(signal.SIGTERM)
    assert procs[serving].wait(timeout=10) == 0
    predictor.alive.wait_gone(token(serving), timeout=5)
    assert {ask_one(client, payload).instance for _ in range(5)} == {"pa", "pb"} - {serving}


def _instances(answers: list[Answer]) -> list[str]:
    return [a.instance if isinstance(a, PredictReply) else a for a in answers]


# -- (d) unknown digest, no model queryable ------------------------------------------------


def test_model_fetch_failures(client: zenoh.Session, predictor: Launcher, system: System, model: ModelBundle) -> None:
    predictor("p1")  # --fetch-timeout 1
    # no model queryable for this digest: the fetch returns at once
    digest = "0" * 32
    answers, took = ask(client, encode(request(system, digest)))
    assert [(a.ok, a.digest, a.error) for a in answers] == [  # type: ignore[union-attr]
        (False, digest, f"cannot fetch model skinet/spot_arm/model/{digest}: no reply")]
    assert took < 1.0
    # a bundle that does not hash to the digest it is served under
    digest = "f" * 32
    ModelServer(client, model, digest=digest)
    reply = ask_one(client, encode(request(system, digest)))
    assert reply.error == f"cannot fetch model skinet/spot_arm/model/{digest}: bundle hashes to {model.digest}"
    # a frozen model server: Zenoh's timeout error after --fetch-timeout
    server = ModelServer(client, model, frozen=True)
    answers, took = ask(client, encode(request(system, model.digest)))
    server.close()
    assert 0.9 < took < QUERY_TIMEOUT, took
    assert len(answers) == 1 and isinstance(answers[0], PredictReply), answers
    assert answers[0].error == f"cannot fetch model skinet/spot_arm/model/{model.digest}: error reply: Timeout"
    # nothing was cached: once the model is served, the same digest is answered
    ModelServer(client, model)
    assert ask_one(client, encode(request(system, model.digest))).ok


# -- in-process: shared session, busy, cache ------------------------------------------------


@pytest.fixture
def peer() -> Iterator[zenoh.Session]:
    """One session for everything, as in the embedded default (no router)."""
    config = session_config("peer", listen=["tcp/127.0.0.1:0"], multicast_scouting=False)
    config.insert_json5("scouting/delay", "0")
    session = zenoh.open(config)
    yield session
    session.close()


def test_embedded_on_a_shared_session(peer: zenoh.Session, system: System, model: ModelBundle) -> None:
    server = ModelServer(peer, model)
    handle = start_predictor(peer, "embedded")
    reply = ask_one(peer, encode(request(system, model.digest, ARM_READY)))
    assert (reply.ok, reply.instance, server.queries) == (True, "embedded", 1)
    assert [str(r.ok.key_expr) for r in peer.liveliness().get(token("*"))] == [token("embedded")]
    handle.close()
    handle.close()  # idempotent
    assert ask(peer, encode(request(system, model.digest)))[0] == []
    assert list(peer.liveliness().get(token("*"))) == []
    assert handle.counts["ok"] == 1


def test_full_pool_answers_busy(peer: zenoh.Session, system: System, model: ModelBundle) -> None:
    server = ModelServer(peer, model, frozen=True)  # the first request holds the only slot
    handle = start_predictor(peer, "tiny", workers=1, max_pending=1, fetch_timeout=0.3, rate_limit=0)
    try:
        first: list[list[Answer]] = []
        slow = threading.Thread(target=lambda: first.append(ask(peer, encode(request(system, model.digest)))[0]))
        slow.start()
        deadline = time.monotonic() + 2
        while server.queries == 0 and time.monotonic() < deadline:  # admitted and fetching
            time.sleep(0.005)
        reply = ask_one(peer, encode(request(system, model.digest, seq=2)), client="other")
        assert (reply.ok, reply.error, reply.seq) == (False, "busy: too many pending requests", 2)
        # The same client: its share (half of max_pending, at least 1) is taken.
        reply = ask_one(peer, encode(request(system, model.digest, seq=3)))
        assert (reply.ok, reply.error, reply.seq) == (False, "busy: client 'local' has its share of pending "
                                                             "requests (1)", 3)
        slow.join()
        assert first[0][0].error == f"cannot fetch model skinet/spot_arm/model/{model.digest}: error reply: Timeout"
        assert (handle.counts["busy"], handle.counts["failed"]) == (2, 1)
    finally:
        handle.close()
        server.close()


def test_lru_cache_of_systems(peer: zenoh.Session, system: System, model: ModelBundle) -> None:
    other = model.model_copy(update={"properties": model.properties + "\n# another revision\n"})
    other = bundle(system_from_bundle(other))
    servers = [ModelServer(peer, model), ModelServer(peer, other)]
    for size, fetches in ((1, 3), (2, 2)):
        handle = start_predictor(peer, f"cache{size}", cache_size=size)
        try:
            for b in (model, other, model):
                assert ask_one(peer, encode(request(system, b.digest))).ok
            assert handle.counts["fetched"] == fetches
        finally:
            handle.close()
    assert sum(s.queries for s in servers) == 5




# -- bounded requests (issue 25, item 6) ---------------------------------------------------


def test_oversized_and_ill_typed_requests_are_refused(peer: zenoh.Session, system: System, model: ModelBundle,
                                                      caplog: pytest.LogCaptureFixture) -> None:
    """Refused with a one-line error, counted and logged (a few lines for a flood), nothing computed."""
    server = ModelServer(peer, model)
    handle = start_predictor(peer, "strict", workers=1, max_request=4096, rate_limit=0)
    try:
        good = request(system, model.digest).model_dump(mode="json")
        # A well-formed request, its marking padded past the limit: refused by its size, unread.
        padded = {**good, "skillsets": {**good["skillsets"],
                                        "spot": {"resources": {f"r{i}": "x" * 64 for i in range(80)}, "running": []}}}
        big = msgpack.packb(padded)
        cases: list[tuple[bytes, str]] = [
            (big, f"request of {len(big)} bytes exceeds the limit of 4096"),
            (msgpack.packb({**good, "budget": "1.0"}), "invalid PredictRequest: budget: Input should be a valid number"),
            (msgpack.packb({**good, "budget": True}), "invalid PredictRequest: budget: Input should be a valid number"),
            (msgpack.packb({**good, "seq": 1.0}), "invalid PredictRequest: seq: Input should be a valid integer"),
            (msgpack.packb({**good, "budget": float("nan")}),
             "invalid PredictRequest: budget: Input should be a finite number"),
            (msgpack.packb({**good, "budget": 0.01}),
             "invalid PredictRequest: budget: Input should be greater than or equal to 0.05"),
        ]
        with caplog.at_level("WARNING", logger="skinet.predictor"):
            for payload, error in cases:
                reply = ask_one(peer, payload)
                assert (reply.ok, reply.error, reply.instance) == (False, error, "strict")
            for _ in range(12):  # a flood: counted, logged at the 1st, 10th, 100th, then every 1000th
                assert ask_one(peer, big).error.startswith("request of ")
            assert ask_one(peer, encode(request(system, model.digest))).ok  # still serving
        assert (handle.counts["refused"], handle.counts["ok"], server.queries) == (18, 1, 1)
        lines = [r.getMessage() for r in caplog.records if "refused request" in r.getMessage()]
        assert lines == [f"predictor strict: refused request spot_arm/0 (#1): request of {len(big)} bytes exceeds "
                         "the limit of 4096",
                         "predictor strict: refused request spot_arm/0 (#10): request of "
                         f"{len(big)} bytes exceeds the limit of 4096"]
    finally:
        handle.close()
        server.close()


def test_monitor_refuses_a_budget_below_the_predictors_minimum(peer: zenoh.Session, system: System) -> None:
    """It would never ask (every answer needs at least MIN_BUDGET), and its checks would never know why."""
    with pytest.raises(ValueError) as info:
        start_monitor(peer, system, budget=0.01)
    assert str(info.value) == ("budget 0.01 s is below the predictor's minimum of 0.05 s: "
                               "no prediction could ever be asked for")
    with pytest.raises(ValueError) as info:
        start_monitor(peer, system, budget=1.0, query_timeout=1.0)
    assert str(info.value) == "query timeout 1 s is not above the budget 1 s: no prediction could ever arrive in time"
    with pytest.raises(ValueError) as info:  # past one day the query timeout would mean "never" (issue 30)
        start_monitor(peer, system, budget=1e308)
    assert str(info.value) == "budget 1e+308 s is above the maximum of 86400 s (one day)"


def test_model_bundle_includes_are_never_read(peer: zenoh.Session, system: System,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """A bundle carries its texts: an ``include`` in it names no file the predictor opens (issue 25, item 6)."""
    monkeypatch.setenv("BUNDLE_TEST_SECRET", "s3cr3t-value")  # in /proc/self/environ of the workers
    spot = (REPO / "skillsets" / "spot.rl").read_text()
    hostile = model_of(system, 'include "/proc/self/environ"\ninclude "../../etc/shadow"\n' + spot)
    server = ModelServer(peer, hostile)
    handle = start_predictor(peer, "bundles", workers=1)
    try:
        reply = ask_one(peer, encode(request(system, hostile.digest, ARM_READY)))
        assert reply.ok and reply.risks, reply.error  # answered from the texts alone
        assert b"s3cr3t" not in encode(reply)
    finally:
        handle.close()
        server.close()


def model_of(system: System, spot_text: str) -> ModelBundle:
    """The system's bundle with spot.rl's text replaced (digest recomputed)."""
    b = bundle(system)
    entries = [(n, spot_text if n == "spot.rl" else t, m) for n, t, m in b.skillsets]
    return bundle(system_from_bundle(b.model_copy(update={"skillsets": entries, "digest": ""})))


# -- per-client rate limit (issue 14) ----------------------------------------------------


def test_rate_limit_per_client(client: zenoh.Session, predictor: Launcher, system: System,
                               model: ModelBundle) -> None:
    """A client over its budget is refused at once; another client is still answered.

    Without access control the client chunk is the caller's choice (the ACL test,
    ``tests/deploy/test_rate_limit.py``, shows it cannot be forged behind the router).
    """
    ModelServer(client, model)
    predictor("p1", "--rate-limit", "2", "--rate-burst", "3")
    payload = encode(request(system, model.digest))
    flood = [ask(client, payload, client="flooder") for _ in range(8)]
    oks = [a for (answers, _) in flood for a in answers if isinstance(a, PredictReply) and a.ok]
    refused = [(a, took) for (answers, took) in flood for a in answers if isinstance(a, PredictReply) and not a.ok]
    assert 3 <= len(oks) <= 4 and len(oks) + len(refused) == 8, flood  # the burst, maybe one refilled
    assert {a.error for a, _ in refused} == {"rate limited: client 'flooder' exceeds 2 requests/s (burst 3)"}
    assert all(took < 0.5 for _, took in refused), "refused at once, not queued"
    other = ask_one(client, payload)  # client "local": its own bucket
    assert other.ok and other.risks is not None
    # A wildcard in the client chunk is no client: an error reply, nothing computed.
    answers, _ = ask(client, payload, client="*")
    assert answers == ["error: key 'skinet/spot_arm/predict/*': the client chunk must be a name "
                       "(skinet/<system>/predict/<client>)"]


def test_new_client_names_share_one_budget(client: zenoh.Session, predictor: Launcher, system: System,
                                           model: ModelBundle) -> None:
    """Issue 31: a client asking under a new name each time gets the new names' budget (the burst, then
    ``--rate-limit`` names a second), not a full bucket per name."""
    ModelServer(client, model)
    predictor("p1", "--rate-limit", "2", "--rate-burst", "3")
    payload = encode(request(system, model.digest))
    t0 = time.monotonic()
    flood = [ask(client, payload, client=f"bad{i}") for i in range(10)]
    seconds = time.monotonic() - t0
    replies = [a for (answers, _) in flood for a in answers if isinstance(a, PredictReply)]
    oks = [a for a in replies if a.ok]
    refused = {a.error for a in replies if not a.ok}
    assert len(replies) == 10 and 3 <= len(oks) <= 3 + 2 * seconds, (seconds, flood)
    assert refused == {"rate limited: too many new clients (more than 2 new names/s, 1024 clients at most); "
                       "ask again under a name already used"}
