"""A Zenoh router on 127.0.0.1 and its clients, as the tests and the benchmarks run a chain (multicast scouting off:
they neither see nor disturb other Zenoh traffic on the machine; docs/deployment.md's layout, one router and
clients).  Cost: a session each; a free port is one bind."""

from __future__ import annotations

import socket

import zenoh

from services.common.zenoh_config import session_config


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_endpoint() -> str:
    """``tcp/127.0.0.1:PORT`` on a :func:`free_port`."""
    return f"tcp/127.0.0.1:{free_port()}"


def open_router(endpoint: str) -> zenoh.Session:
    """A Python session in router mode listening on ``endpoint``."""
    config = session_config("router", listen=[endpoint], multicast_scouting=False)
    config.insert_json5("scouting/delay", "0")  # nothing to scout: open at once, not after 0.5 s
    return zenoh.open(config)


def open_client(endpoint: str) -> zenoh.Session:
    """A client session connected to the router at ``endpoint``."""
    return zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))


def client_args(endpoint: str) -> list[str]:
    """Command-line flags making a service a client of the router at ``endpoint``."""
    return ["--mode", "client", "--connect", endpoint, "--no-multicast-scouting"]


def loopback_router(clients: int) -> tuple[str, zenoh.Session, list[zenoh.Session]]:
    """A router on a free port (its endpoint and session) and ``clients`` client sessions of it."""
    endpoint = free_endpoint()
    router = open_router(endpoint)
    return endpoint, router, [open_client(endpoint) for _ in range(clients)]
