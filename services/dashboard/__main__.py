"""``python -m services.dashboard SYSTEM``: the live web dashboard as a process (docs/semantics.md §7)."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.common.cli import one_line_errors
from services.common.options import ArgumentParser
from services.dashboard.app import add_dashboard_args, serve
from services.common.cli import stop_on_signals


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="python -m services.dashboard",
        description="SkiNet Live dashboard: a web page showing a running system live (skillsets, properties, "
                    "unsafe commands with their kind, steps and witness, predictions, violations, timeline), "
                    "fed by a Zenoh observer; its goal box gives goals to the system's pilot (docs/semantics.md §8) under "
                    "this process's login (only operator-role users may).")
    add_dashboard_args(parser)
    return parser


@one_line_errors("python -m services.dashboard")
def main(argv: Sequence[str] | None = None) -> int:
    return serve(build_parser().parse_args(argv), stop_on_signals())


if __name__ == "__main__":
    sys.exit(main())
