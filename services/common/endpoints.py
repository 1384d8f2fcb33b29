"""Zenoh endpoints checked as text (``PROTOCOL/ADDRESS``, a port for IP protocols), before any
session is opened: what both the environment table and the Zenoh options use.  Cost: two regex matches."""

from __future__ import annotations

import re

from skinet.errors import SkinetError


# Protocols whose address is HOST:PORT (the others, e.g. unixsock-stream, take a path).
_IP_PROTOCOLS = {"tcp", "udp", "tls", "quic", "ws"}


_ENDPOINT = re.compile(r"^(?P<proto>[a-z][a-z0-9+\-]*)/(?P<address>[^?#]+)(?:\?[^#]*)?(?:#.*)?$")


_HOST_PORT = re.compile(r"^(?P<host>\[[0-9A-Fa-f:.]+\]|[^:\[\]]+):(?P<port>[^:]*)$")


class ZenohSetupError(SkinetError):
    """A Zenoh option, configuration file or session that cannot be used (one line)."""


def check_endpoint(endpoint: str, option: str) -> str:
    """``PROTOCOL/ADDRESS`` with a port in 0-65535 for IP protocols; raises :class:`ZenohSetupError`."""
    m = _ENDPOINT.match(endpoint)
    if m is None:
        raise ZenohSetupError(f"{option} '{endpoint}': an endpoint is PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")
    if m["proto"] in _IP_PROTOCOLS:
        hp = _HOST_PORT.match(m["address"])
        if hp is None:
            raise ZenohSetupError(f"{option} '{endpoint}': the address must be HOST:PORT, e.g. tcp/127.0.0.1:7447")
        if not hp["port"].isdigit() or int(hp["port"]) > 65535:
            raise ZenohSetupError(f"{option} '{endpoint}': port '{hp['port']}' is not a number from 0 to 65535")
    return endpoint
