"""Why a Zenoh client could not open its session: a refused login (SPEC §7).

Zenoh reports every failed client connection as ``Unable to connect to any of
[...]``, whether nothing listens there or the router refused the login.  When
opening fails, :func:`login_refused` probes the endpoints with a plain TCP
connection: a router that accepts TCP but refused the session is, in practice,
refusing the credentials (or their absence).  Used by
:func:`services.common.zenoh_config.open_session`.
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


def login_refused(config: zenoh.Config) -> str | None:
    """The reason when a router at one of ``config``'s endpoints accepts TCP (so it refused the
    login), else None (nothing answers there)."""
    user = _get(config, "transport/auth/usrpwd/user")
    endpoints = [e for e in (_get(config, "connect/endpoints") or []) if isinstance(e, str)]
    reached = [e for e in endpoints if _tcp_open(e)]
    if not reached:
        return None
    for endpoint in reached:
        if endpoint.startswith("tls/"):
            problem = _tls_problem(config, endpoint)
            if problem:
                return f"the router at {endpoint} refused the TLS handshake: {problem}"
    login = (f"authentication failed for user '{user}' (check SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, "
             f"or --user and --password)" if user else
             "it requires a user and password (set SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, "
             "or --user and --password)")
    return f"the router at {', '.join(reached)} refused the login: {login}"


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
