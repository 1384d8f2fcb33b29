"""Command-line pieces every service shares: instance ids, logging, one-line errors, ROS 2 key styles."""

from __future__ import annotations

import argparse
import functools
import logging
import os
import re
import signal
import socket
import sys
import threading
from collections.abc import Callable, Sequence

from services.common.environment import check_environment
from services.common.stacks import stacks_on_sigusr1
from services.common.options import count, key_name, key_prefix
from skinet.errors import SkinetError, SourceError
from skinet.ros.keys import KeyStyle

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")


def default_instance_id() -> str:
    """``<host>-<pid>``, reduced to the characters a Zenoh key chunk allows."""
    return re.sub(r"[^A-Za-z0-9_\-.]", "_", f"{socket.gethostname()}-{os.getpid()}")


def add_instance_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--instance", type=key_name("instance id"),
                        default=os.environ.get("SKINET_INSTANCE") or default_instance_id(),
                        help="instance id in the liveliness token (default: $SKINET_INSTANCE or HOST-PID)")


def add_ros_key_args(parser: argparse.ArgumentParser) -> None:
    """``--rmw-zenoh``, ``--namespace``, ``--domain``, ``--ros-distro``: how ROS 2 topics and services show on Zenoh
    (:func:`key_style`), for the services that read or write them (the bridge, the pilot)."""
    parser.add_argument("--rmw-zenoh", action="store_true",
                        help="topics as rmw_zenoh carries them (default: zenoh-bridge-ros2dds keys)")
    parser.add_argument("--namespace", type=key_prefix("namespace", env="SKINET_ROS_NAMESPACE"),
                        default=os.environ.get("SKINET_ROS_NAMESPACE", ""),
                        help="zenoh-bridge-ros2dds namespace prefixing the keys")
    parser.add_argument("--domain", type=count(0, 232, env="ROS_DOMAIN_ID"), default=os.environ.get("ROS_DOMAIN_ID", "0"),
                        help="ROS domain id in rmw_zenoh keys (default: $ROS_DOMAIN_ID or 0)")
    parser.add_argument("--ros-distro", default=os.environ.get("ROS_DISTRO", "jazzy"),
                        help="ROS 2 distribution of rmw_zenoh (default: $ROS_DISTRO or jazzy); on humble the keys "
                             "carry TypeHashNotSupported instead of a RIHS01 type hash")


def key_style(args: argparse.Namespace) -> KeyStyle:
    """The :class:`~skinet.ros.keys.KeyStyle` of :func:`add_ros_key_args`'s options."""
    return KeyStyle(args.rmw_zenoh, args.namespace, args.domain, args.ros_distro == "humble")


def _log_level(text: str) -> str:
    if text.upper() not in LEVELS:
        origin = " (from $SKINET_LOG_LEVEL)" if os.environ.get("SKINET_LOG_LEVEL") == text else ""
        raise argparse.ArgumentTypeError(f"expected one of {', '.join(LEVELS)}, got '{text}'{origin}")
    return text.upper()


def add_log_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--log-level", type=_log_level, default=os.environ.get("SKINET_LOG_LEVEL", "INFO"),
                        help="logging level (default: $SKINET_LOG_LEVEL or INFO)")


def setup_logging(args: argparse.Namespace) -> None:
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")


def one_line_errors(prog: str) -> Callable[[Callable[[Sequence[str] | None], int]], Callable[..., int]]:
    """Wrap a service's ``main``: bad files print ``FILE:LINE:COL: error: ...``, other bad input
    ``PROG: error: ...``, each on one line with exit status 1; Ctrl-C exits 130."""
    def wrap(main: Callable[[Sequence[str] | None], int]) -> Callable[..., int]:
        @functools.wraps(main)
        def guarded(argv: Sequence[str] | None = None) -> int:
            stacks_on_sigusr1()
            try:
                check_environment()
                return main(argv)
            except SourceError as exc:
                print(str(exc), file=sys.stderr)
            except (SkinetError, ValueError) as exc:  # ValueError: a name that is no Zenoh key, a step the simulator cannot drive
                print(f"{prog}: error: {exc}", file=sys.stderr)
            except KeyboardInterrupt:
                return 130
            return 1

        return guarded

    return wrap


def stop_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM (handlers installed only from the main thread)."""
    stop = threading.Event()
    handler: Callable[..., None] = lambda *_: stop.set()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, handler)
    return stop
