"""Helpers of the deployment tests: the ACL router's configuration, logins, and an
observer that turns the monitor's publications into the mission's violations.

Every session here is on 127.0.0.1 with multicast scouting off.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import zenoh

from services.common.security import USERS, ensure_tls, ensure_users, tls_connect_config, tls_listen_config
from skinet.system.load import load_system
from skinet.files.read import read_text
from tests.loopback import client_args, free_port  # noqa: F401  (free_port: the deployment tests and bench_flood)
from tests.processes import start_module, stop_and_show
from skinet.mission.scenario import Scenario, parse_scenario, replay
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.convert import bundle
from skinet.wire.messages import (
    CanonicalEvent, LiveState, PredictReply, PredictRequest, StateSpaceReport, UnsafeReport, Verdicts,
)

REPO = Path(__file__).resolve().parents[2]
ZENOH_DIR = REPO / "docker" / "zenoh"
ROUTER_CONFIG = ZENOH_DIR / "router.json5"
# No password is in the repository: the tests make their own, as an operator would.
SECRETS = Path(tempfile.mkdtemp(prefix="skinet-test-secrets-"))
USERS_FILE = SECRETS / "users.txt"
TLS = SECRETS / "tls"  # the tests' CA, with a certificate for the router and each user
UNASSISTED = REPO / "skillsets" / "missions" / "unassisted.toml"
SYSTEM = "spot_arm"


def passwords() -> dict[str, str]:
    """The users of a test run (made at first use in ``SECRETS``, with their certificates): user -> password."""
    ensure_tls(TLS, ["router", *USERS])
    return ensure_users(SECRETS)


def acl_router_config(endpoint: str, askers: tuple[str, ...] = (), tcp_twins: bool = True) -> zenoh.Config:
    """``docker/zenoh/router.json5`` as shipped, listening on ``endpoint``, users made by the tests.

    On a ``tls/`` endpoint the router serves the tests' certificate of ``router`` and the
    access control is the shipped one.  On ``tcp/`` (tests of the rules, and clients built
    without TLS) no client has a certificate for the shipped subjects to check, so with
    ``tcp_twins`` each subject gets a twin matching its user names on tcp links alone
    (``test_acl.py`` checks the binding of certificates to users over TLS).
    ``askers``: extra users who may ask predictions and checks under their own name,
    as an operator adds them (docs/deployment.md, "Rate limits").
    """
    config = zenoh.Config.from_file(str(ROUTER_CONFIG))
    passwords()
    for user in askers:
        add_asker(config, user)
    if endpoint.startswith("tcp/") and tcp_twins:
        acl = json.loads(config.get_json("access_control"))
        acl["subjects"] += [{"id": f"{s['id']} over tcp", "usernames": s["usernames"], "link_protocols": ["tcp"]}
                            for s in acl["subjects"]]
        for policy in acl["policies"]:
            policy["subjects"] = [*policy["subjects"], *(f"{s} over tcp" for s in policy["subjects"])]
        config.insert_json5("access_control", json.dumps(acl))
    if endpoint.startswith("tls/"):
        config.insert_json5("transport/link/tls", json.dumps(tls_listen_config(TLS, "router")))
    config.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(USERS_FILE)))
    config.insert_json5("listen/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/delay", "0")
    return config


def add_asker(config: zenoh.Config, user: str) -> None:
    """Let ``user`` (made in ``SECRETS``, with its certificate) read, and ask checks and
    predictions under its own name only."""
    ensure_users(SECRETS, [user])
    ensure_tls(TLS, [user])
    acl = json.loads(config.get_json("access_control"))
    acl["rules"].append({"id": f"{user} asks", "permission": "allow", "flows": ["ingress"], "messages": ["query"],
                         "key_exprs": [f"skinet/*/check/{user}", f"skinet/*/predict/{user}",
                                       f"skinet/*/predict/{user}/*"]})
    acl["subjects"].append({"id": user, "usernames": [user], "cert_common_names": [user]})
    next(p for p in acl["policies"] if p["id"] == "everybody reads")["subjects"].append(user)
    acl["policies"].append({"id": f"{user} asks", "rules": [f"{user} asks"], "subjects": [user]})
    config.insert_json5("access_control", json.dumps(acl))


def login_config(endpoint: str, user: str | None, password: str | None = None,
                 certificate: str | None = None) -> zenoh.Config:
    """A client configuration for ``endpoint``; ``user`` None: no credentials at all.

    On a ``tls/`` endpoint the client presents the tests' certificate of ``certificate``
    (default: ``user``'s; none when both are None).
    """
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    if user is not None:
        config.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        config.insert_json5("transport/auth/usrpwd/password",
                            json.dumps(passwords()[user] if password is None else password))
    name = certificate or user
    if endpoint.startswith("tls/"):
        passwords()  # the certificates
        tls = tls_connect_config(TLS, name) if name else {"root_ca_certificate": str(TLS / "ca.pem")}
        config.insert_json5("transport/link/tls", json.dumps(tls))
    return config


def login(endpoint: str, user: str | None, password: str | None = None, certificate: str | None = None) -> zenoh.Session:
    return zenoh.open(login_config(endpoint, user, password, certificate))


class Services:
    """Service processes (``python -m MODULE``), each a client of a router logged in as its user.

    Output goes to ``folder/<module>-<n>.log``, printed when :meth:`close` stops them.
    """

    def __init__(self, folder: Path):
        self.folder = folder
        self.procs: list[tuple[subprocess.Popen, Path]] = []

    def start(self, module: str, user: str, router: str, *args: str) -> subprocess.Popen:
        cfg = write_login_file(self.folder / f"{user}-{len(self.procs)}.json5", user)
        log = self.folder / f"{module}-{len(self.procs)}.log"
        proc = start_module(module, *args, *client_args(router), "--zenoh-config", str(cfg), log=log)
        self.procs.append((proc, log))
        return proc

    def log(self, proc: subprocess.Popen) -> str:
        return next(log for p, log in self.procs if p is proc).read_text(errors="replace")

    def close(self) -> None:
        stop_and_show(self.procs, tail=3000)


def write_login_file(path: Path, user: str) -> Path:
    """A JSON5 file with ``user``'s credentials (password; certificate for ``tls/`` routers),
    for a service's ``--zenoh-config``."""
    password = passwords()[user]
    path.write_text(json.dumps({"transport": {"auth": {"usrpwd": {"user": user, "password": password}},
                                              "link": {"tls": tls_connect_config(TLS, user)}}}))
    return path


class Tokens:
    """Live liveliness tokens under ``skinet/**`` (services announce themselves there)."""

    def __init__(self, session: zenoh.Session, key_expr: str = "skinet/**"):
        self._lock = threading.Lock()
        self.alive: set[str] = set()
        self.appeared: dict[str, float] = {}  # token -> last appearance (monotonic)
        self._sub = session.liveliness().declare_subscriber(key_expr, self._on, history=True)

    def _on(self, sample: zenoh.Sample) -> None:
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(str(sample.key_expr))
                self.appeared[str(sample.key_expr)] = time.monotonic()
            else:
                self.alive.discard(str(sample.key_expr))

    def of(self, service: str, since: float | None = None) -> set[str]:
        """Instance ids of ``service`` (``skinet/<system>/alive/<service>/<id>``) alive now,
        and announced after ``since`` (monotonic) when given."""
        with self._lock:
            return {k.split("/")[4] for k in self.alive if k.split("/")[3:4] == [service]
                    and (since is None or self.appeared[k] >= since)}

    def close(self) -> None:
        self._sub.undeclare()


def wait_until(predicate: Callable[[], bool], timeout: float, what: str, poll: float = 0.05) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(poll)


def answering_predictor(session: zenoh.Session, system_file: Path = REPO / "skillsets" / "spot_arm.toml",
                        user: str = "monitor") -> str:
    """Instance id of the predictor the router picks for a query now (the one serving
    the monitor: ZENOH.md, the first live instance declared); ``session`` is logged in as ``user``."""
    system, _ = load_system(system_file)
    request = PredictRequest(system=system.name, digest=bundle(system).digest, seq=1, skillsets={}, budget=0.2)
    for reply in session.get(keys.predict(system.name, user), payload=encode(request), timeout=5.0):
        if reply.ok is not None:
            return decode(reply.ok.payload.to_bytes(), PredictReply).instance
    raise AssertionError("no predictor answered")


# -- the mission's violations ----------------------------------------------------------


@dataclass(frozen=True)
class Violation:
    """A property that became false at one scenario step."""

    step: int  # 1-based index in the scenario (skinet.mission.scenario.replay numbering)
    skillset: str
    transition: str
    property: str


def expected_violations(scenario_path: Path = UNASSISTED) -> list[Violation]:
    """What the in-process replay of the scenario gives (no prediction needed for verdicts)."""
    scenario = parse_scenario(read_text(scenario_path), str(scenario_path))
    system, _ = load_system(scenario_path.parent / scenario.system)
    return [Violation(r.index, r.step.skillset, r.step.transition or "", p)
            for r in replay(system, scenario, predict=False) for p in r.violations]


def load_scenario(path: Path = UNASSISTED) -> Scenario:
    return parse_scenario(read_text(path), str(path))


class MissionObserver:
    """Records the monitor's state, verdicts and unsafe reports of one system.

    A violation is a property that holds in one ``Verdicts`` and not in the next; its
    event is the ``LiveState`` of the same ``seq`` (``skillset:transition#n``), and its
    scenario step comes from :func:`align`.

    ``after``: the monitor's last step before the mission (its ``seq``).  The monitor
    publishes that step again whenever a skillset's sync state changes (same ``seq``,
    the old event's name); such a copy is no step of the mission and is left out.
    """

    def __init__(self, session: zenoh.Session, system: str = SYSTEM, after: int = -1):
        self._lock = threading.Lock()
        self.after = after
        self.states: dict[int, LiveState] = {}
        self.verdicts: dict[int, Verdicts] = {}
        self.unsafe: list[tuple[float, UnsafeReport]] = []  # (arrival, report)
        self.state_space: list[tuple[float, StateSpaceReport]] = []
        self.arrivals: dict[tuple[str, int], float] = {}  # ("state"|"verdicts", seq) -> arrival
        self.event_arrivals: dict[tuple[str, int], float] = {}  # (skillset, event seq) -> arrival
        self.event_log: list[tuple[float, float, str]] = []  # (arrival, source stamp, skillset:transition#seq)
        self.last_arrival = 0.0
        self._subs = [
            session.declare_subscriber(keys.events(system, "*"), self._on(CanonicalEvent, self._event)),
            session.declare_subscriber(keys.state(system), self._on(LiveState, self._state)),
            session.declare_subscriber(keys.verdicts(system), self._on(Verdicts, self._verdicts)),
            session.declare_subscriber(keys.unsafe(system), self._on(UnsafeReport, self._unsafe)),
            session.declare_subscriber(keys.state_space(system), self._on(StateSpaceReport, self._space)),
        ]

    def _on(self, kind, store):
        def callback(sample: zenoh.Sample) -> None:
            try:
                message = decode(sample.payload.to_bytes(), kind)
            except DecodeError:
                return
            now = time.monotonic()
            with self._lock:
                self.last_arrival = now
                store(now, message)
        return callback

    def _event(self, now: float, m: CanonicalEvent) -> None:
        self.event_arrivals.setdefault((m.skillset, m.seq), now)
        self.event_log.append((now, m.stamp, f"{m.skillset}:{m.transition}#{m.seq}"))

    def _state(self, now: float, m: LiveState) -> None:
        if m.seq <= self.after:
            return
        self.states[m.seq] = m
        self.arrivals.setdefault(("state", m.seq), now)

    def _verdicts(self, now: float, m: Verdicts) -> None:
        if m.seq <= self.after:
            return
        self.verdicts[m.seq] = m
        self.arrivals.setdefault(("verdicts", m.seq), now)

    def _unsafe(self, now: float, m: UnsafeReport) -> None:
        self.unsafe.append((now, m))

    def _space(self, now: float, m: StateSpaceReport) -> None:
        self.state_space.append((now, m))

    def count(self) -> int:
        with self._lock:
            return len(self.states)

    def verdict_delays(self, since: float = 0.0) -> dict[str, float]:
        """Seconds from a canonical event to the monitor's verdicts on it, per event, for
        events that arrived after ``since`` (monotonic)."""
        with self._lock:
            out = {}
            for seq, st in self.states.items():
                name, _, n = st.event.rpartition("#")
                skillset = name.partition(":")[0]
                sent = self.event_arrivals.get((skillset, int(n))) if n.isdigit() else None
                got = self.arrivals.get(("verdicts", seq))
                if sent is not None and sent >= since and got is not None:
                    out[st.event] = got - sent
            return out

    def fresh_delays(self, since: float = 0.0) -> dict[int, float | None]:
        """Per state seq published after ``since``: seconds until a fresh (not stale)
        UnsafeReport for it or a later seq arrived; None if none did."""
        with self._lock:
            fresh = [(t, r.seq) for t, r in self.unsafe if not r.prediction_stale]
            out: dict[int, float | None] = {}
            for (kind, seq), t in self.arrivals.items():
                if kind == "state" and t >= since:
                    # A report of seq >= this one follows this state, whatever its arrival stamp: each
                    # key's callback runs in a Python thread of its own, so a report published right after
                    # its state (a cached prediction, the mission's last marking) may be stamped first.
                    later = [max(ft, t) for ft, fs in fresh if fs >= seq]
                    out[seq] = min(later) - t if later else None
            return dict(sorted(out.items()))

    def marking(self, seq: int) -> str:
        """The live marking of state ``seq``, as canonical JSON."""
        with self._lock:
            st = self.states.get(seq)
        return "" if st is None else json.dumps({k: v.model_dump() for k, v in st.skillsets.items()}, sort_keys=True)

    def fresh(self, start: float = 0.0, end: float = float("inf")) -> list[tuple[float, int]]:
        """``(arrival, seq)`` of the fresh UnsafeReports that arrived in ``[start, end)``."""
        with self._lock:
            return [(t, r.seq) for t, r in self.unsafe if not r.prediction_stale and start <= t < end]

    def states_between(self, start: float, end: float = float("inf")) -> list[int]:
        with self._lock:
            return sorted(seq for (kind, seq), t in self.arrivals.items() if kind == "state" and start <= t < end)

    def close(self) -> None:
        for sub in self._subs:
            try:
                sub.undeclare()
            except zenoh.ZError:
                pass

    def quiet_for(self, seconds: float) -> bool:
        with self._lock:
            return bool(self.states) and time.monotonic() - self.last_arrival >= seconds

    def event_trace(self) -> str:
        """The canonical events as this observer received them, with their source stamps (for failures)."""
        with self._lock:
            log = list(self.event_log)
        t0 = log[0][0] if log else 0.0
        return "\n".join(f"{arrival - t0:8.3f} {stamp:.3f} {name}" for arrival, stamp, name in log)

    def events(self) -> list[tuple[int, str, str]]:
        """``(seq, skillset, transition)`` of every state published, in seq order."""
        with self._lock:
            states = sorted(self.states.items())
        out = []
        for seq, st in states:
            head = st.event.rsplit("#", 1)[0]
            skillset, _, transition = head.partition(":")
            out.append((seq, skillset, transition))
        return out

    def violations(self, scenario: Scenario) -> list[Violation]:
        with self._lock:
            verdicts = sorted(self.verdicts.items())
        events = self.events()
        steps = align(scenario, events)
        by_seq = {seq: (skillset, transition) for seq, skillset, transition in events}
        out: list[Violation] = []
        before: dict[str, bool] | None = None
        for seq, v in verdicts:
            now = {p.name: p.holds for p in v.properties}
            if before is not None:
                for name, ok in now.items():
                    if before.get(name, True) and not ok:
                        skillset, transition = by_seq.get(seq, ("?", "?"))
                        out.append(Violation(steps.get(seq, 0), skillset, transition, name))
            before = now
        return out


def align(scenario: Scenario, events: list[tuple[int, str, str]]) -> dict[int, int]:
    """Scenario step (1-based) of each monitor event, by skillset: seq -> step.

    Per skillset, events arrive in the scenario's order, but some have no step of
    their own (the bridge's first status absorbs what happened before it; invariant
    failures follow from other steps): each named event is matched with the next
    step of its skillset playing the same transition, and skipped when there is none.
    """
    out: dict[int, int] = {}
    position: dict[str, int] = {}  # skillset -> index of the last matched step
    for seq, skillset, transition in events:
        start = position.get(skillset, 0)
        for i in range(start, len(scenario.steps)):
            step = scenario.steps[i]
            if step.skillset == skillset and step.transition == transition:
                out[seq] = i + 1
                position[skillset] = i + 1
                break
    return out
