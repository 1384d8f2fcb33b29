"""Opening a Zenoh session with an error that says why it failed (SPEC §7).

Zenoh reports every failed client connection as ``Unable to connect to any of
[...]``, whether nothing listens there or the router refused the login.  When
opening fails, :func:`open_session` probes the endpoints with a plain TCP
connection: a router that accepts TCP but refused the session is, in practice,
refusing the credentials (or their absence), and the error says so.
"""

from __future__ import annotations

import json
import re
import socket

import zenoh

from skinet.errors import SkinetError

PROBE_TIMEOUT = 1.0


class SessionError(SkinetError):
    """A Zenoh session could not be opened; the message is one line."""


def open_session(config: zenoh.Config) -> zenoh.Session:
    """``zenoh.open(config)``, raising :class:`SessionError` with the likely cause."""
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        raise SessionError(diagnose(config, str(exc))) from None


def _get(config: zenoh.Config, path: str) -> object:
    try:
        return json.loads(config.get_json(path))
    except Exception:  # absent key
        return None


def diagnose(config: zenoh.Config, error: str) -> str:
    """One line explaining ``error`` (Zenoh's message) for a session of ``config``."""
    user = _get(config, "transport/auth/usrpwd/user")
    endpoints = [e for e in (_get(config, "connect/endpoints") or []) if isinstance(e, str)]
    reached = [e for e in endpoints if _tcp_open(e)]
    if reached:
        login = (f"authentication failed for user '{user}' (check SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, "
                 f"or --user and --password)" if user else
                 "it requires a user and password (set SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, "
                 "or --user and --password)")
        return f"the Zenoh router at {', '.join(reached)} refused the session: {login}"
    first = error.split("  at ")[0].strip()  # drop Zenoh's source location
    if endpoints:
        return f"cannot open a Zenoh session: no router answers at {', '.join(endpoints)} ({first})"
    return f"cannot open a Zenoh session: {first}"


def _tcp_open(endpoint: str) -> bool:
    """Whether ``tcp/HOST:PORT`` (or ``tls/``) accepts a TCP connection now."""
    m = re.fullmatch(r"(?:tcp|tls)/\[?([^\]]+?)\]?:(\d+)(?:#.*)?", endpoint)
    if m is None:
        return False
    try:
        with socket.create_connection((m.group(1), int(m.group(2))), timeout=PROBE_TIMEOUT):
            return True
    except OSError:
        return False
