"""Why a Zenoh session could not connect: nothing answers, or a refused login (docs/semantics.md §7).

Zenoh reports every failed client connection as ``Unable to connect to any of
[...]``, whether nothing listens there or the router refused the login.  When
opening fails, :func:`login_refused` probes the endpoints with a plain TCP
connection: a router that accepts TCP but refused the session is, in practice,
refusing the credentials (or their absence).

A peer (or a router) does not fail at all: it opens without the endpoints it
could not reach and keeps trying in the background (ZENOH.md).
:func:`unconnected` finds the ``connect`` endpoints that no link of the session
leads to, and :func:`connect_problem` says why, with the same probes.  Used by
:func:`services.common.zenoh_config.open_session`.  Cost: one TCP (and TLS)
handshake per endpoint probed, at most ``PROBE_TIMEOUT`` each.
"""

from __future__ import annotations

import json
import re
import socket
import ssl

import zenoh

PROBE_TIMEOUT = 1.0


def _get(config: zenoh.Config, path: str) -> object:
    try:
        return json.loads(config.get_json(path))
    except Exception:  # absent key
        return None


def unconnected(session: zenoh.Session, config: zenoh.Config) -> list[str]:
    """The ``connect`` endpoints of a peer or router session that no link of ``session`` leads to
    (a client connects to one of them only, and fails to open without it)."""
    if _get(config, "mode") == "client":
        return []
    linked = {_address(str(link.dst)) for link in session.info.links()}
    missing = [e for e in _endpoints(config) if _address(e) not in linked]
    if missing and linked:  # a host name: compare its addresses with the links'
        missing = [e for e in missing if not _resolved(e) & linked]
    return missing


def connect_problem(config: zenoh.Config, endpoint: str) -> str:
    """Why ``endpoint`` gives no session: ``nothing answers there``, or what the router there refused."""
    if not _tcp_open(endpoint):
        return "nothing answers there"
    if endpoint.startswith("tls/"):
        problem = _tls_problem(config, endpoint)
        if problem:
            return f"the router refused the TLS handshake: {problem}"
    return f"the router refused the login: {_login_reason(config)}"


def login_refused(config: zenoh.Config) -> str | None:
    """The reason when a router at one of ``config``'s endpoints accepts TCP (so it refused the
    login), else None (nothing answers there)."""
    reached = [e for e in _endpoints(config) if _tcp_open(e)]
    if not reached:
        return None
    for endpoint in reached:
        if endpoint.startswith("tls/"):
            problem = _tls_problem(config, endpoint)
            if problem:
                return f"the router at {endpoint} refused the TLS handshake: {problem}"
    return f"the router at {', '.join(reached)} refused the login: {_login_reason(config)}"


def _login_reason(config: zenoh.Config) -> str:
    user = _get(config, "transport/auth/usrpwd/user")
    if user:
        return (f"authentication failed for user '{user}' (check SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, "
                "or --user and --password)")
    return ("it requires a user and password (set SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, "
            "or --user and --password)")


def _endpoints(config: zenoh.Config) -> list[str]:
    """The ``connect`` endpoints (of this mode, when the file gives them per mode)."""
    endpoints = _get(config, "connect/endpoints") or []
    if isinstance(endpoints, dict):
        endpoints = endpoints.get(_get(config, "mode") or "peer") or []
    return [e for e in endpoints if isinstance(e, str)]


_ADDRESS = re.compile(r"(?P<proto>[a-z0-9+\-]+)/\[?(?P<host>[^\]?#]+?)\]?:(?P<port>\d+)(?:[?#].*)?")


def _address(endpoint: str) -> tuple[str, str, str] | str:
    """``(protocol, host, port)`` of an endpoint or link locator (the text itself when it has no port)."""
    m = _ADDRESS.fullmatch(endpoint)
    return endpoint if m is None else (m["proto"], m["host"], m["port"])


def _resolved(endpoint: str) -> set[tuple[str, str, str] | str]:
    """:func:`_address` of ``endpoint`` with its host name replaced by each of its addresses."""
    address = _address(endpoint)
    if isinstance(address, str):
        return set()
    try:
        infos = socket.getaddrinfo(address[1], int(address[2]), type=socket.SOCK_STREAM)
    except OSError:
        return set()
    return {(address[0], str(info[4][0]), address[2]) for info in infos}


def _tls_problem(config: zenoh.Config, endpoint: str) -> str | None:
    """Why a TLS handshake with ``config``'s certificates fails at ``endpoint``, or None when it succeeds."""
    m = re.fullmatch(r"tls/\[?([^\]]+?)\]?:(\d+)(?:[?#].*)?", endpoint)
    if m is None:
        return None
    tls = _get(config, "transport/link/tls") or {}
    ca = tls.get("root_ca_certificate") if isinstance(tls, dict) else None
    if not ca:
        return "this client has no CA certificate (transport/link/tls/root_ca_certificate)"
    try:
        context = ssl.create_default_context(cafile=ca)
        context.check_hostname = False  # Zenoh checks the name itself; here only the chain matters
        cert, key = tls.get("connect_certificate"), tls.get("connect_private_key")
        if cert and key:
            context.load_cert_chain(cert, key)
        with socket.create_connection((m.group(1), int(m.group(2))), timeout=PROBE_TIMEOUT) as raw:
            with context.wrap_socket(raw) as conn:
                conn.recv(1)  # TLS 1.3: a refused client certificate shows up at the first read
    except (ssl.SSLError, OSError) as exc:
        if isinstance(exc, (socket.timeout, TimeoutError)):
            return None  # the handshake went through; the router is waiting for Zenoh's hello
        reason = getattr(exc, "reason", None) or str(exc)
        return f"{reason} (check the CA and this client's certificate)"
    return None


def _tcp_open(endpoint: str) -> bool:
    """Whether ``tcp/HOST:PORT`` (or ``tls/``) accepts a TCP connection now."""
    m = re.fullmatch(r"(?:tcp|tls)/\[?([^\]]+?)\]?:(\d+)(?:[?#].*)?", endpoint)
    if m is None:
        return False
    try:
        with socket.create_connection((m.group(1), int(m.group(2))), timeout=PROBE_TIMEOUT):
            return True
    except OSError:
        return False
