"""Command-line pieces every service shares: instance ids, logging, one-line errors."""

from __future__ import annotations

import argparse
import functools
import logging
import os
import re
import socket
import sys
from collections.abc import Callable, Sequence

from skinet_cli.environment import check_environment
from skinet_cli.options import key_name
from skinet.errors import SkinetError, SourceError

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")


def default_instance_id() -> str:
    """``<host>-<pid>``, reduced to the characters a Zenoh key chunk allows."""
    return re.sub(r"[^A-Za-z0-9_\-.]", "_", f"{socket.gethostname()}-{os.getpid()}")


def add_instance_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--instance", type=key_name("instance id"),
                        default=os.environ.get("SKINET_INSTANCE") or default_instance_id(),
                        help="instance id in the liveliness token (default: $SKINET_INSTANCE or HOST-PID)")


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
