"""The ``--memory-limit`` option shared by ``skinet explore/unsafe/ctl/plan/run`` and the pilot (docs/semantics.md
§6.1)."""

from __future__ import annotations

import argparse

from skinet.system.load import load_memory_limit, parse_size
from skinet.verify.explore import DEFAULT_MEMORY_LIMIT


TRUNCATED = "beyond it the answer is truncated, never refused"


def add_memory_arg(c: argparse.ArgumentParser, beyond: str = TRUNCATED) -> None:
    """``--memory-limit``; ``beyond`` says what the command does past it."""
    c.add_argument("--memory-limit", type=memory_size, metavar="SIZE",
                   help="peak memory of the whole process, e.g. 512MiB (default: the system file's "
                        f"[system] memory_limit, else 1GiB); {beyond}")


def memory_size(text: str) -> int:
    """argparse type of a size in bytes (``--memory-limit``, ``--incidents-max-bytes``): ``512MiB``, ``2GB``, ..."""
    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def memory_limit(args: argparse.Namespace) -> int:
    """``--memory-limit``, else the system file's setting, else 1 GiB."""
    return args.memory_limit or load_memory_limit(args.system) or DEFAULT_MEMORY_LIMIT
