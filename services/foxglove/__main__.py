"""``python -m services.foxglove SYSTEM``: the live Foxglove connection as a process (docs/foxglove.md)."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.common.cli import one_line_errors
from services.common.options import ArgumentParser
from services.common.cli import stop_on_signals
from services.foxglove.app import add_foxglove_args, serve
from services.foxglove.feed import pipe_fd


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="python -m services.foxglove",
        description="SkiNet Live in Foxglove: a Foxglove WebSocket server (foxglove.websocket.v1) serving a running "
                    "system's state, verdicts, unsafe commands, violations, divergences, state space, pilot, "
                    "plot series and log lines, fed by a read-only Zenoh observer.")
    add_foxglove_args(parser)
    parser.add_argument("--feed", type=pipe_fd, metavar="FD",
                        help="the monitor's results come through the pipe open as file descriptor FD, not from Zenoh, "
                             "and the view ends with the pipe (how skinet run --foxglove starts it; "
                             "docs/foxglove.md)")
    return parser


@one_line_errors("python -m services.foxglove")
def main(argv: Sequence[str] | None = None) -> int:
    return serve(build_parser().parse_args(argv), stop_on_signals())


if __name__ == "__main__":
    sys.exit(main())
