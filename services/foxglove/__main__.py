"""``python -m services.foxglove SYSTEM``: the live Foxglove connection as a process (docs/foxglove.md)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from services.common.cli import one_line_errors
from services.common.cli import stop_on_signals
from services.foxglove.app import add_foxglove_args, serve


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m services.foxglove",
        description="SkiNet Live in Foxglove: a Foxglove WebSocket server (foxglove.websocket.v1) serving a running "
                    "system's state, verdicts, unsafe commands, violations, divergences, state space, pilot, "
                    "plot series and log lines, fed by a read-only Zenoh observer.")
    add_foxglove_args(parser)
    return parser


@one_line_errors("python -m services.foxglove")
def main(argv: Sequence[str] | None = None) -> int:
    return serve(build_parser().parse_args(argv), stop_on_signals())


if __name__ == "__main__":
    sys.exit(main())
