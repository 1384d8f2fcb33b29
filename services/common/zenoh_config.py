"""One way of configuring Zenoh for every service (flags as in zenoh-python's examples).

Environment variables give the defaults so containers need no arguments:
``SKINET_ZENOH_MODE`` (peer|client|router), ``SKINET_ZENOH_CONNECT`` and
``SKINET_ZENOH_LISTEN`` (comma-separated endpoints such as
``tcp/127.0.0.1:7447``), ``SKINET_ZENOH_CONFIG`` (a JSON5 file),
``SKINET_ZENOH_USER`` with ``SKINET_ZENOH_PASSWORD`` or ``SKINET_ZENOH_PASSWORD_FILE``
(user/password login), ``SKINET_ZENOH_SCOUTING=1`` (multicast scouting, off by default).

Secure defaults (issue 14): a peer or router given no ``listen`` endpoint listens
on loopback only (``LOOPBACK``), and multicast scouting is off unless asked for.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import re
import sys
import time
from collections.abc import Callable

import zenoh

from services.common.endpoints import ZenohSetupError, check_endpoint
from services.common.session import connect_problem, login_refused, unconnected
from skinet.errors import Pos, SkinetError, SourceError, shown
from skinet.files.read import FileRefused, read_bytes, read_text
from skinet.wire import keys
from services.common.environment import flag

_log = logging.getLogger("skinet.zenoh")
LOOPBACK = "tcp/127.0.0.1:0"  # a peer's default endpoint: this host only, any free port
ROUTER_LOOPBACK = "tcp/127.0.0.1:7447"  # a router's

MODES = ("peer", "client", "router")
MAX_PASSWORD_FILE = 4096  # bytes: a password file is one line
_RUST_PLACE = re.compile(r"\s+at \S+\.rs:\d+\.?")  # " at /root/.cargo/.../x.rs:62." in ZError texts
_JSON_MESSAGE = re.compile(r'msg: "(?P<msg>(?:[^"\\]|\\.)*)", location: Some\(Location \{ line: (?P<line>\d+), '
                           r"column: (?P<col>\d+)")
_JSON5_SYNTAX = re.compile(r"-->\s*(?P<line>\d+):(?P<col>\d+).*?=\s*(?P<msg>[^\n]+)", re.S)


def _clean(text: str) -> str:
    """One line, without Rust source places and a final full stop."""
    return " ".join(_RUST_PLACE.sub("", text.replace('\\"', '"')).split()).rstrip(".")


def zenoh_reason(exc: BaseException) -> str:
    """The human part of a ZError, on one line."""
    m = _JSON_MESSAGE.search(str(exc))
    return _clean(str(exc) if m is None else m["msg"])


def load_config_file(path: str) -> zenoh.Config:
    """A JSON5 Zenoh configuration file; errors name the file (and line:column when Zenoh gives one)."""
    read_text(path)  # a missing or unreadable file (or a folder): the usual "cannot read file" error
    try:
        return zenoh.Config.from_file(path)
    except zenoh.ZError as exc:
        m = _JSON_MESSAGE.search(str(exc)) or _JSON5_SYNTAX.search(str(exc))
        pos = None if m is None else Pos(int(m["line"]), int(m["col"]))
        reason = zenoh_reason(exc) if m is None else _clean(m["msg"])
        raise SourceError.at(path, pos, f"invalid Zenoh configuration: {reason}") from None


def open_session(config: zenoh.Config, warn: Callable[[str], None] | None = None) -> zenoh.Session:
    """``zenoh.open`` with a one-line :class:`ZenohSetupError` (port in use, nobody to connect to, ...).

    A client that reaches none of its ``connect`` endpoints fails here.  A peer or
    a router opens anyway and keeps trying: each endpoint it could not reach is
    reported at once through ``warn`` (default: a log warning), with the reason.
    """
    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:
        reason = zenoh_reason(exc)
        busy = re.search(r"bound to (\S+): \[.*Address already in use", reason)
        if busy:
            reason = f"cannot listen on {busy[1]}: address already in use"
        unreachable = re.match(r"Unable to connect to any of \[(.*)\]", reason)
        if unreachable:
            endpoints = re.findall(r"\(([^()]*)\)", unreachable[1]) or [unreachable[1]]
            reason = login_refused(config) or f"nothing answers at {', '.join(endpoints)}"
        raise ZenohSetupError(f"cannot open the Zenoh session: {reason}") from None
    for problem in connect_problems(session, config):
        (warn or _log.warning)(f"{problem}; Zenoh keeps trying in the background")
    return session


def connect_problems(session: zenoh.Session, config: zenoh.Config) -> list[str]:
    """``cannot connect to E: REASON`` for each ``connect`` endpoint ``session`` has no link to
    (peers and routers; empty for a client, which has one, or failed to open)."""
    return [f"cannot connect to {shown_endpoint(e)}: {connect_problem(config, e)}"
            for e in unconnected(session, config)]


def shown_endpoint(endpoint: str) -> str:
    """An endpoint as messages name it: without its settings (``?...``, ``#...``)."""
    return re.sub(r"[?#].*", "", endpoint)


def wait_connected(session: zenoh.Session, config: zenoh.Config, timeout: float) -> bool:
    """Whether every ``connect`` endpoint has a link within ``timeout`` seconds (Zenoh retries them)."""
    deadline = time.monotonic() + timeout
    while unconnected(session, config):
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.1)
    return True


def check_connected(session: zenoh.Session, config: zenoh.Config) -> None:
    """Raise :class:`ZenohSetupError` naming every ``connect`` endpoint still unreached, with the reason:
    what a command that needs the connection says when its timeout ends."""
    problems = connect_problems(session, config)
    if problems:
        raise ZenohSetupError("; ".join(problems))


def add_zenoh_args(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("zenoh")
    g.add_argument("--mode", "-m", choices=MODES, default=os.environ.get("SKINET_ZENOH_MODE") or None,
                   help="session mode (default: $SKINET_ZENOH_MODE, else client with --user and --connect: a "
                        "router login, else peer)")
    g.add_argument("--connect", "-e", action="append", default=None,
                   help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--listen", "-l", action="append", default=None, help="endpoint to listen on (repeatable)")
    g.add_argument("--zenoh-config", default=os.environ.get("SKINET_ZENOH_CONFIG"), help="JSON5 Zenoh configuration file")
    add_scouting_args(g)
    add_login_args(g)


def add_login_args(g: argparse._ActionsContainer) -> None:
    """``--user``/``--password``/``--password-file`` (defaults from ``SKINET_ZENOH_*``)."""
    g.add_argument("--user", default=os.environ.get("SKINET_ZENOH_USER") or None,
                   help="user/password login to the router (default: $SKINET_ZENOH_USER)")
    g.add_argument("--password", default=os.environ.get("SKINET_ZENOH_PASSWORD") or None,
                   help="password of --user (default: $SKINET_ZENOH_PASSWORD)")
    g.add_argument("--password-file", default=os.environ.get("SKINET_ZENOH_PASSWORD_FILE") or None,
                   help="read the password from this file (default: $SKINET_ZENOH_PASSWORD_FILE)")


def login(args: argparse.Namespace) -> dict[str, str | None]:
    """``user`` and ``password`` keywords of :func:`session_config` from the flags of
    :func:`add_login_args`; :class:`SkinetError` on an unreadable password file."""
    user, password = getattr(args, "user", None), getattr(args, "password", None)
    path = getattr(args, "password_file", None)
    if path:
        try:
            password = read_bytes(path, MAX_PASSWORD_FILE)[0].decode("utf-8", errors="replace").strip()
        except FileRefused as exc:  # a FIFO or a folder too: refused, never waited on
            raise SkinetError(f"cannot read password file {shown(path)}: "
                              f"{exc.reason.removeprefix('cannot read file: ')}") from None
    return {"user": user, "password": password}


def add_scouting_args(g: argparse._ActionsContainer) -> None:
    """``--multicast-scouting`` (off by default); ``--no-multicast-scouting`` is kept for old scripts."""
    g.add_argument("--multicast-scouting", action="store_true", default=flag("SKINET_ZENOH_SCOUTING"),
                   help="join multicast scouting to find peers on the LAN (default: off; $SKINET_ZENOH_SCOUTING=1)")
    g.add_argument("--no-multicast-scouting", action="store_true", help="the default; accepted for old scripts")


def _env_list(name: str) -> list[str]:
    return [e.strip() for e in os.environ.get(name, "").split(",") if e.strip()]


def session_config(
    mode: str = "peer",
    connect: list[str] | None = None,
    listen: list[str] | None = None,
    config_file: str | None = None,
    multicast_scouting: bool = False,
    user: str | None = None,
    password: str | None = None,
) -> zenoh.Config:
    """A Zenoh configuration from explicit settings (endpoints in ``tcp/HOST:PORT`` form).

    Without ``listen``, a peer or router listens on loopback only, unless the file
    ``config_file`` says where; multicast scouting is off unless asked for.
    Raises :class:`ZenohSetupError` or :class:`SourceError` (the file) with one line.
    """
    if mode not in MODES:
        raise ZenohSetupError(f"Zenoh mode '{mode}' is not one of {', '.join(MODES)}")
    for option, endpoints in (("--connect", connect), ("--listen", listen)):
        for endpoint in endpoints or ():
            check_endpoint(endpoint, option)
    config = load_config_file(config_file) if config_file else zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(connect))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(listen))
    elif mode != "client" and config.get_json("listen/endpoints") == zenoh.Config().get_json("listen/endpoints"):
        config.insert_json5("listen/endpoints", json.dumps([LOOPBACK if mode == "peer" else ROUTER_LOOPBACK]))
    config.insert_json5("scouting/multicast/enabled", json.dumps(multicast_scouting))
    if user:
        config.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
    if password is not None:  # else keep the configuration file's (the container entry point writes it there)
        config.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return config


def session_mode(args: argparse.Namespace, connect: list[str], command: bool = False) -> str:
    """``--mode``, else ``$SKINET_ZENOH_MODE`` (checked: argparse does not check choices on a default from
    the environment), else the ``mode`` the ``--zenoh-config`` file sets, else ``client`` when a user logs in
    to an endpoint of ``connect`` (a router: a peer would reach no other peer through it), or when
    ``command`` (a command line's session) connects to any endpoint and listens on none: a peer session
    through a router reaches the router's clients only now and then (docs/deployment.md), else ``peer``."""
    if args.mode is None:
        path = getattr(args, "zenoh_config", None)
        if path:
            mode = json.loads(load_config_file(path).get_json("mode"))
            if mode != json.loads(zenoh.Config().get_json("mode")):
                return str(mode)
        if connect and (getattr(args, "user", None) or command):
            return "client"
        return "peer"
    if args.mode not in MODES:
        raise ZenohSetupError(f"SKINET_ZENOH_MODE '{args.mode}' is not one of {', '.join(MODES)}")
    return str(args.mode)


def said_at_the_end(message: str) -> None:
    """A ``warn`` for :func:`open_session` in a command that waits a bounded time for its endpoints and then
    fails with :func:`check_connected`: the error says it then, in one line, not twice."""


def warn_on_stderr(prog: str) -> Callable[[str], None]:
    """A ``warn`` for :func:`open_session` that prints ``PROG: warning: ...`` at once (commands)."""
    return lambda message: print(f"{prog}: warning: {message}", file=sys.stderr, flush=True)


def config_from_args(args: argparse.Namespace, command: bool = False) -> zenoh.Config:
    """The session configuration of a service's flags (``command``: a command line's, see
    :func:`session_mode`); bad environment values are named as such."""
    endpoints = {}
    for option, env in (("connect", "SKINET_ZENOH_CONNECT"), ("listen", "SKINET_ZENOH_LISTEN")):
        endpoints[option] = getattr(args, option)
        if endpoints[option] is None:
            endpoints[option] = [check_endpoint(e, env) for e in _env_list(env)]
    mode = session_mode(args, endpoints["connect"], command and not endpoints["listen"])
    return session_config(mode, endpoints["connect"], endpoints["listen"], args.zenoh_config,
                          args.multicast_scouting, **login(args))


def client_name(config: zenoh.Config) -> str:
    """The client chunk of this session's ``predict`` and ``check`` keys: its router login
    (``transport/auth/usrpwd/user``), or ``local`` without one (``skinet.wire.keys``, issue 14).

    The router's access control lets user ``U`` query only keys whose client chunk is
    ``U``, so a service must ask under its own login name.
    """
    user = json.loads(config.get_json("transport/auth/usrpwd/user") or "null")
    if not user:
        return keys.LOCAL_CLIENT
    try:
        return keys.check_chunk(str(user), "user name")
    except ValueError as exc:
        raise ZenohSetupError(f"{exc}: a user whose queries carry its name must be a key chunk") from None


def undeclare(*entities: object) -> None:
    """Undeclare Zenoh entities, ignoring those whose session is already closed."""
    for entity in entities:
        try:
            entity.undeclare()  # type: ignore[attr-defined]
        except zenoh.ZError:
            pass  # session already closed


def zenoh_error(exc: Exception) -> str:
    """A Zenoh error in one line, without the Rust source location (`` at .../x.rs:12.``)."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?$", "", " ".join(str(exc).split()))
