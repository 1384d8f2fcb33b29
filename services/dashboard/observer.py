"""A read-only Zenoh observer of one system, feeding a :class:`Board` (docs/semantics.md §7).

Subscribes to the monitor's five result keys (or to its feed, the same in rounds: the Foxglove view), the
pilot's status (docs/semantics.md §8) and to the liveliness tokens of the system's services and of the
predictors; when a monitor or a pilot appears (at start, or after a restart) it fetches the model bundle and the
last publications (the monitor and the pilot answer ``get`` on their keys), so a view opened mid-mission is
complete at once.  It publishes nothing and declares nothing a read-only ACL role refuses; goals go to the pilot
only when the page sends one (:meth:`Observer.goal`), under the session's login.  Listeners get every update,
called from Zenoh's threads with the observer's lock held: they must not block.  The served views (the
dashboard, Foxglove) share their options and their start here (:func:`add_view_args`, :func:`observe`,
:func:`follow`).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import zenoh
from pydantic import BaseModel

from services.common.goals import ask_pilot
from services.common.options import count, load_live_system, seconds
from services.common.zenoh_config import (
    check_connected, client_name, config_from_args, open_session, said_at_the_end, undeclare,
)
from services.dashboard.board import Board, Update
from services.monitor.check import parse_command
from skinet.errors import SkinetError
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode, validate
from skinet.wire.limits import FEED_STEPS
from skinet.wire.convert import system_from_bundle
from skinet.wire.messages import (
    CheckReply, Divergences, LiveState, ModelBundle, PilotGoalReply, PilotGoalRequest, PilotStatus, ResultFeed,
    StateSpaceReport, UnsafeReport, Verdicts,
)

Listener = Callable[[list[Update]], None]
# Asked in this order when catching up: the list first (a violation's onset at its own step, not at the one
# shown), the state before the verdicts and report of its step.
MONITOR_RESULTS: tuple[tuple[Callable[[str], str], type[BaseModel]], ...] = (
    (keys.divergences, Divergences), (keys.state, LiveState), (keys.verdicts, Verdicts),
    (keys.unsafe, UnsafeReport), (keys.state_space, StateSpaceReport),
)
RESULTS = (*MONITOR_RESULTS, (keys.pilot_status, PilotStatus))
FED: dict[str, type[BaseModel]] = {key.__name__: kind for key, kind in MONITOR_RESULTS}  # a ResultFeed's kinds
FOLLOW_UP = 0.5  # seconds after a monitor appeared that its last publications are asked again
QUERY_TIMEOUT = 2.0


def monitored_systems(session: zenoh.Session, timeout: float = 1.0) -> list[str]:
    """Names of the systems whose monitor holds a liveliness token now."""
    found = set()
    for reply in session.liveliness().get(keys.alive("*", "monitor", "*"), timeout=timeout):
        if reply.ok is not None:
            found.add(str(reply.ok.key_expr).split("/")[1])
    return sorted(found)


class Observer:
    """Follows ``system`` on ``session`` (which may be shared, e.g. ``skinet run``)."""

    def __init__(self, session: zenoh.Session, system: str, model: System | None = None, history: int = 5000,
                 client: str = keys.LOCAL_CLIENT, goal_login: tuple[zenoh.Session, str] | None = None,
                 fed: bool = False, feed: bool = False):
        """``client``: the client chunk of its check queries, the session's router login
        (:func:`~services.common.zenoh_config.client_name`); ``goal_login``: the session and login the
        goals are sent from, when not this session's (an operator's, beside an observer's); ``fed``: the
        monitor's results (:data:`MONITOR_RESULTS`) come from elsewhere (:meth:`take`, :meth:`fetch_results`; a
        pipe from ``skinet run``'s monitor, :mod:`services.foxglove.feed`), not from Zenoh; ``feed``: they come
        in rounds on the monitor's feed key (:mod:`services.monitor.feed`: one Zenoh message per round, not one per
        result), asked on the monitor's keys as usual when a monitor appears or a round was lost."""
        self.session = session
        self._goal_login = goal_login
        self.name = keys.check_chunk(system, "system name")
        self.client = keys.check_chunk(client, "client name")
        self.board = Board(self.name, history, model)
        self._model = model  # the system file's; else rebuilt from the monitor's bundle (:meth:`model`)
        self._bundled: tuple[str, System | None] | None = None  # (digest, system) of the last bundle rebuilt
        self.malformed = 0
        self._lock = threading.Lock()
        self._listeners: list[Listener] = []
        self._resync = threading.Event()
        self._closed = threading.Event()
        self._monitor_seen = threading.Event()
        self.fetched = threading.Event()  # the last publications were asked for once (a view's first picture)
        self._asked = RESULTS[len(MONITOR_RESULTS):] if fed else RESULTS
        self._feed_at: tuple[str, int] | None = None  # (monitor, seq) of the last round of the feed
        self._fetching = False  # the last publications are being asked: a round may be older than their answers
        self._feed_older = 0  # rounds after the last answers that may be older than them
        self.feed_gaps = 0  # rounds of the feed lost (each asked the monitor's last results again)
        self.fetches = 0  # times the model and the last publications were asked
        subscribed = RESULTS[len(MONITOR_RESULTS):] if fed or feed else RESULTS
        self._subs = [session.declare_subscriber(key(self.name), self._on_sample(kind)) for key, kind in subscribed]
        if feed and not fed:
            self._subs.append(session.declare_subscriber(keys.feed(self.name), self._on_feed))
        live = session.liveliness()
        self._tokens = [live.declare_subscriber(k, self._on_token, history=True)
                        for k in (keys.alive(self.name, "*", "*"), keys.alive(keys.ANY_SYSTEM, "predictor", "*"))]
        self._thread = threading.Thread(target=self._sync, name="skinet-observer-sync", daemon=True)
        self._thread.start()
        self._resync.set()

    # -- public API ---------------------------------------------------------------------

    def listen(self, listener: Listener) -> Update:
        """Add ``listener`` and return the snapshot it starts from (atomically)."""
        with self._lock:
            self._listeners.append(listener)
            return self.board.snapshot()

    def unlisten(self, listener: Listener) -> None:
        with self._lock:
            if listener in self._listeners:
                self._listeners.remove(listener)

    def snapshot(self) -> Update:
        with self._lock:
            return self.board.snapshot()

    def read(self, fn: Callable[[Board], object]) -> object:
        """``fn(board)`` under the lock (consistent reads for terminal views)."""
        with self._lock:
            return fn(self.board)

    def wait_monitor(self, timeout: float) -> bool:
        """Whether a monitor of the system is (or becomes) alive within ``timeout`` seconds."""
        return self._monitor_seen.wait(timeout)

    def check(self, command: str, timeout: float = QUERY_TIMEOUT) -> CheckReply:
        """Ask the monitor's command check; raises :class:`LookupError` when no monitor answers
        and ``ValueError`` for a command that is not ``skillset:transition``."""
        request = parse_command(command)
        key = keys.check(self.name, self.client)
        for reply in self.session.get(key, payload=encode(request), timeout=timeout):
            if reply.ok is not None:
                return decode(reply.ok.payload.to_bytes(), CheckReply)
        raise LookupError(f"no monitor of system '{self.name}' answered on {key}")

    def model(self) -> System | None:
        """The system: the file's, else the monitor's model bundle rebuilt (None before one came)."""
        if self._model is not None:
            return self._model
        with self._lock:
            bundle = self.board.model
        if bundle is None:
            return None
        if self._bundled is None or self._bundled[0] != bundle.digest:
            try:
                self._bundled = (bundle.digest, system_from_bundle(bundle))
            except SkinetError:
                self._bundled = (bundle.digest, None)
        return self._bundled[1]

    def goal(self, request: PilotGoalRequest, timeout: float) -> PilotGoalReply:
        """Ask the pilot under the goal login, else this session's; raises :class:`~services.common.goals.NoPilot`."""
        session, client = self._goal_login or (self.session, self.client)
        return ask_pilot(session, request, client, timeout)

    def close(self) -> None:
        self._closed.set()
        self._resync.set()
        undeclare(*self._subs, *self._tokens)
        self._thread.join(timeout=QUERY_TIMEOUT + 1)

    # -- Zenoh callbacks ----------------------------------------------------------------

    def _on_sample(self, kind: type[BaseModel]) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind == zenoh.SampleKind.PUT:
                self.take(sample.payload.to_bytes(), kind, False)
        return on_sample

    def take(self, payload: bytes, kind: type[BaseModel], initial: bool) -> None:
        """One message of the system as ``kind`` (counted as malformed when it is not; ``initial``: it may be an
        older copy of what is shown, e.g. an answer to a ``get``)."""
        try:
            message = decode(payload, kind)
        except DecodeError:
            with self._lock:
                self.malformed += 1
            return
        with self._lock:
            if message.system != self.name:  # type: ignore[attr-defined]
                self.malformed += 1
                return
            self._emit(self.board.feed(message, time.time(), initial))

    def _on_feed(self, sample: zenoh.Sample) -> None:
        """A round of the monitor's feed: its messages in order, as if they came on their keys; a round lost (its
        seq jumps) asks the monitor's last results again."""
        if sample.kind != zenoh.SampleKind.PUT:
            return
        try:
            feed = decode(sample.payload.to_bytes(), ResultFeed)
            messages = [validate(r.message, FED[r.kind]) for r in feed.results]
        except DecodeError:
            with self._lock:
                self.malformed += 1
            return
        with self._lock:
            if feed.system != self.name or any(m.system != self.name for m in messages):  # type: ignore[attr-defined]
                self.malformed += 1
                return
            last, self._feed_at = self._feed_at, (feed.monitor, feed.seq)
            lost = last is not None and last[0] == feed.monitor and feed.seq != last[1] + 1
            older = self._fetching or self._feed_older > 0
            self._feed_older = max(0, self._feed_older - 1)
            now = time.time()
            for message in messages:
                self._emit(self.board.feed(message, now, older))
            if feed.skipped:
                self._emit([{"kind": "skipped", "steps": feed.skipped, "most": FEED_STEPS, "round": feed.round}])
            if lost:
                self.feed_gaps += 1
        if lost:
            self._resync.set()

    def _on_token(self, sample: zenoh.Sample) -> None:
        key, alive = str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            self._emit(self.board.token(key, alive))
        if alive and key.split("/")[1:4:2] == [self.name, "monitor"]:
            self._monitor_seen.set()
            self._resync.set()
        elif alive and key.split("/")[1:4:2] == [self.name, "pilot"]:
            self._resync.set()  # its status

    def _emit(self, updates: list[Update]) -> None:
        if updates:
            for listener in list(self._listeners):
                listener(updates)

    # -- start-up and resynchronisation -------------------------------------------------

    def _sync(self) -> None:
        """Fetch the model and the last publications whenever a monitor (re)appears, and once more
        ``FOLLOW_UP`` s later: a publication made while this session's subscriptions were still on their way
        to the publisher's reaches neither them nor an answer given before it (a replay at speed 0 publishes
        its whole run in that window); the second look gets the last ones."""
        while True:
            self._resync.wait()
            self._resync.clear()
            if self._closed.is_set() or not self._fetch_all():
                return
            if self._resync.wait(FOLLOW_UP):
                continue  # a new monitor or pilot came meanwhile: that round looks at once, and again later
            if self._closed.is_set() or not self._fetch_all():
                return

    def _fetch_all(self) -> bool:
        """The model and the last publications, asked once; False when the session was closed under us."""
        self._fetching = True
        try:
            if not self._fetch_each(((keys.model, ModelBundle), *self._asked)):
                return False
        finally:
            with self._lock:
                self._fetching, self._feed_older = False, 2  # rounds put before the answers may come after them
                self.fetches += 1
        self.fetched.set()
        return True

    def note(self, update: Update) -> None:
        """Hand the listeners an update of the feeder's own (a fed view that skipped steps says so)."""
        with self._lock:
            self._emit([update])

    def fetch_results(self) -> bool:
        """The monitor's last results (:data:`MONITOR_RESULTS`), asked now, in the caller's thread (a fed observer
        catching up); False when the session was closed under us."""
        return self._fetch_each(MONITOR_RESULTS)

    def _fetch_each(self, asked: Sequence[tuple[Callable[[str], str], type[BaseModel]]]) -> bool:
        """The last publication on each key of ``asked``, in order; False when the session was closed under us."""
        try:
            for key, kind in asked:
                self._fetch(key(self.name), kind)
        except zenoh.ZError:
            return False
        return True

    def _fetch(self, key: str, kind: type[BaseModel]) -> None:
        for reply in self.session.get(key, timeout=QUERY_TIMEOUT):
            if reply.ok is not None and not self._closed.is_set():
                self.take(reply.ok.payload.to_bytes(), kind, True)


def add_view_args(p: argparse.ArgumentParser, env: tuple[str, str], port: int, system_help: str) -> None:
    """A served view's SYSTEM, ``--host`` and ``--port`` (defaults from the variables ``env`` names: host, port)
    and ``--wait``: the dashboard's and the Foxglove view's."""
    host_env, port_env = env
    p.add_argument("system", metavar="SYSTEM", help=system_help)
    p.add_argument("--host", default=os.environ.get(host_env, "127.0.0.1"),
                   help=f"address to serve on (default: ${host_env} or 127.0.0.1; 0.0.0.0 exposes it)")
    p.add_argument("--port", "-p", type=count(0, 65535, env=port_env),
                   default=os.environ.get(port_env, str(port)),
                   help=f"TCP port (default: ${port_env} or {port}; 0 picks a free one)")
    p.add_argument("--wait", type=seconds(zero=True), default=5.0,
                   help="seconds before warning that no monitor of the system is alive (default: 5)")


def resolve_system(spec: str) -> tuple[str, System | None]:
    """(name, system) from a system file, or (name, None) from a bare name (:class:`SkinetError`
    when it cannot be a Zenoh key chunk)."""
    if spec.endswith(".toml") or Path(spec).is_file():
        system, _ = load_live_system(spec)
        return system.name, system
    try:
        return keys.check_chunk(spec, "system name"), None
    except ValueError as exc:
        raise SkinetError(str(exc)) from None


def goal_config(args: argparse.Namespace, config: zenoh.Config) -> zenoh.Config | None:
    """The Zenoh configuration of the goal box's own login (the dashboard's ``--goal-user``), at the router
    ``config`` connects to; ``None`` without one (a view with no such option).  :class:`SkinetError` (one line)
    for what cannot log in."""
    user = getattr(args, "goal_user", None)
    if not user:
        return None
    from services.common.zenoh_config import login, session_config
    from services.common.client_files import client_config, client_files

    connect = json.loads(config.get_json("connect/endpoints") or "[]")
    if not connect:
        raise SkinetError(f"--goal-user {user} logs in to a router: give its endpoint with --connect/-e")
    folder = Path(getattr(args, "goal_secrets", None) or os.environ.get("SKINET_SECRETS")
                  or Path.home() / ".config" / "skinet" / "secrets")
    tls = [e for e in connect if e.startswith("tls/")]
    if tls:  # the router binds certificates to users: the goal login brings its own
        return zenoh.Config.from_json5(json.dumps(client_config(client_files(folder, user), tls[0])))
    password = login(argparse.Namespace(user=user, password=None, password_file=str(folder / f"{user}.password")))
    return session_config("client", connect, user=user, password=password["password"])


@dataclass
class View:
    """What a served view observes through: its Zenoh configuration, session and observer, and the goal box's own
    session when it has a login of its own (:func:`goal_config`); :meth:`close` closes them all."""

    config: zenoh.Config
    session: zenoh.Session
    observer: Observer
    goal_session: zenoh.Session | None = None

    def close(self) -> None:
        self.observer.close()
        self.session.close()
        if self.goal_session is not None:
            self.goal_session.close()


def observe(args: argparse.Namespace, feed: bool = False) -> View:
    """A served view of the system ``args.system`` names: the session of ``args``' Zenoh options and, with a
    goal login (``args.goal_user``), a second session the observer sends goals from; with ``args.feed`` (a pipe
    from ``skinet run``), an observer fed the monitor's results from elsewhere, else with ``feed`` one that takes
    them in rounds from the monitor's feed key (the Foxglove view).  Raises a one-line
    :class:`SkinetError` (a bad system, a missing secret: before any session is opened; no router, a refused
    login)."""
    name, system = resolve_system(args.system)
    config = config_from_args(args)
    goals = goal_config(args, config)
    session = open_session(config, said_at_the_end)  # an endpoint still unreached after --wait: follow's error
    try:
        goal_session = open_session(goals) if goals is not None else None
    except SkinetError:
        session.close()
        raise
    goal_login = None if goals is None or goal_session is None else (goal_session, client_name(goals))
    observer = Observer(session, name, system, client=client_name(config), goal_login=goal_login,
                        fed=getattr(args, "feed", None) is not None, feed=feed)
    return View(config, session, observer, goal_session)


def follow(observer: Observer, config: zenoh.Config, wait: float, stop: threading.Event,
           log: logging.Logger) -> None:
    """Until ``stop``: warn once when no monitor shows up within ``wait`` seconds (an explicit endpoint still
    unreached is a one-line error instead)."""
    deadline = time.monotonic() + wait
    while not observer.wait_monitor(min(0.1, max(deadline - time.monotonic(), 0.0))):
        if stop.is_set():
            return
        if time.monotonic() >= deadline:
            check_connected(observer.session, config)
            log.warning("%s", no_monitor_message(observer.session, observer.name, config))
            break
    stop.wait()


def no_monitor_message(session, name: str, config: zenoh.Config | None = None) -> str:
    """One line for a system the observer cannot find, naming the systems it can; with no ``connect``
    endpoint in ``config`` (multicast scouting is off by default), how to reach ``skinet run``'s."""
    others = monitored_systems(session)
    seen = f"systems with a monitor: {', '.join(others)}" if others else "no monitor is reachable at all"
    if not others and config is not None and not json.loads(config.get_json("connect/endpoints")):
        seen += ("; no --connect/-e given: `skinet run` and `skinet demo --live` listen on a free port and print "
                 "the -e ENDPOINT to pass")
    return f"no monitor of system '{name}' is alive ({seen}); waiting for one"
