"""One way of configuring Zenoh for every service (flags as in zenoh-python's examples).

Environment variables give the defaults so containers need no arguments:
``SKINET_ZENOH_MODE`` (peer|client|router), ``SKINET_ZENOH_CONNECT`` and
``SKINET_ZENOH_LISTEN`` (comma-separated endpoints such as
``tcp/127.0.0.1:7447``), ``SKINET_ZENOH_CONFIG`` (a JSON5 file),
``SKINET_ZENOH_SCOUTING=1`` (multicast scouting, off by default).

Secure defaults (issue 14): a peer or router given no ``listen`` endpoint listens
on loopback only (``LOOPBACK``), and multicast scouting is off unless asked for.
"""

from __future__ import annotations

import argparse
import json
import os

import zenoh

LOOPBACK = "tcp/127.0.0.1:0"  # a peer's default endpoint: this host only, any free port
ROUTER_LOOPBACK = "tcp/127.0.0.1:7447"  # a router's


def add_zenoh_args(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("zenoh")
    g.add_argument("--mode", "-m", choices=["peer", "client", "router"],
                   default=os.environ.get("SKINET_ZENOH_MODE", "peer"), help="session mode (default: peer)")
    g.add_argument("--connect", "-e", action="append", default=None,
                   help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--listen", "-l", action="append", default=None, help="endpoint to listen on (repeatable)")
    g.add_argument("--zenoh-config", default=os.environ.get("SKINET_ZENOH_CONFIG"), help="JSON5 Zenoh configuration file")
    add_scouting_args(g)


def add_scouting_args(g: argparse._ActionsContainer) -> None:
    """``--multicast-scouting`` (off by default); ``--no-multicast-scouting`` is kept for old scripts."""
    g.add_argument("--multicast-scouting", action="store_true",
                   default=os.environ.get("SKINET_ZENOH_SCOUTING", "") not in ("", "0"),
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
) -> zenoh.Config:
    """A Zenoh configuration from explicit settings (endpoints in ``tcp/HOST:PORT`` form).

    Without ``listen``, a peer or router listens on loopback only, unless the file
    ``config_file`` says where; multicast scouting is off unless asked for.
    """
    config = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(connect))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(listen))
    elif mode != "client" and config.get_json("listen/endpoints") == zenoh.Config().get_json("listen/endpoints"):
        config.insert_json5("listen/endpoints", json.dumps([LOOPBACK if mode == "peer" else ROUTER_LOOPBACK]))
    config.insert_json5("scouting/multicast/enabled", json.dumps(multicast_scouting))
    return config


def config_from_args(args: argparse.Namespace) -> zenoh.Config:
    return session_config(
        args.mode,
        args.connect if args.connect is not None else _env_list("SKINET_ZENOH_CONNECT"),
        args.listen if args.listen is not None else _env_list("SKINET_ZENOH_LISTEN"),
        args.zenoh_config,
        args.multicast_scouting,
    )


def undeclare(*entities: object) -> None:
    """Undeclare Zenoh entities, ignoring those whose session is already closed."""
    for entity in entities:
        try:
            entity.undeclare()  # type: ignore[attr-defined]
        except zenoh.ZError:
            pass  # session already closed
