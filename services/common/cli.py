"""Command-line pieces every service shares: instance ids and logging."""

from __future__ import annotations

import argparse
import logging
import os
import re
import socket


def default_instance_id() -> str:
    """``<host>-<pid>``, reduced to the characters a Zenoh key chunk allows."""
    return re.sub(r"[^A-Za-z0-9_\-.]", "_", f"{socket.gethostname()}-{os.getpid()}")


def add_instance_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--instance", default=os.environ.get("SKINET_INSTANCE") or default_instance_id(),
                        help="instance id in the liveliness token (default: $SKINET_INSTANCE or HOST-PID)")


def add_log_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--log-level", default=os.environ.get("SKINET_LOG_LEVEL", "INFO"),
                        help="logging level (default: $SKINET_LOG_LEVEL or INFO)")


def setup_logging(args: argparse.Namespace) -> None:
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
