"""A Zenoh router on 127.0.0.1 and its clients, as the tests and the benchmarks run a chain (multicast scouting off:
they neither see nor disturb other Zenoh traffic on the machine; docs/deployment.md's layout, one router and
clients).  Cost: a session each; a free port is a bind or a few."""

from __future__ import annotations

import functools
import random
import socket
from pathlib import Path

import zenoh

from services.common.zenoh_config import session_config


PICK = random.SystemRandom()  # not the tests' seeded random: parallel workers must not pick alike
SPAN = 10_000  # free ports are picked among the SPAN ports below the ephemeral range


@functools.cache
def _ephemeral_low() -> int:
    """The lowest port the kernel gives outgoing connections (Linux: 32768 unless configured)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago, below the kernel's ephemeral range: a port the kernel
    picks (bind to 0) can be taken by any outgoing connection before its user binds it (seen once: a compose
    stack's router port, taken in the seconds before compose bound it); this one only by another listener."""
    low = _ephemeral_low()
    if low - SPAN > 1024:  # above the privileged ports
        for _ in range(100):
            port = PICK.randrange(low - SPAN, low)
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
                try:
                    s.bind(("127.0.0.1", port))
                except OSError:
                    continue
                return port
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
