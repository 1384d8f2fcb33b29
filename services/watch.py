"""``skinet watch SYSTEM_NAME``: the terminal operator view of any running deployment (SPEC §7).

A read-only observer (:class:`~services.dashboard.observer.Observer`) follows the
monitor's messages through Zenoh; the view is the one ``skinet run`` draws
(:func:`services.embedded.render`), plus the services alive and the violations
seen: redrawn in place on a terminal, one line per step otherwise; a state the monitor
cannot vouch for (a skillset syncing or lost, SPEC §7) is a banner on top, red or
yellow on a terminal, and ``STATE STALE`` in each line of a pipe.  With no
monitor of the system alive within ``--wait`` seconds it says so, naming the
systems it can see, and exits 1.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from typing import TextIO

from services.common.zenoh_config import client_name, config_from_args, open_session
from services.dashboard.board import Board
from services.dashboard.observer import Observer
from services.dashboard.app import no_monitor_message
from services.embedded import CLEAR, Observed, render, stop_on_signals, summary
from skinet.errors import SkinetError


def view_lines(board: Board, colour: bool = False) -> list[str]:
    """The operator view of what ``board`` holds; empty until the three messages of the
    monitor's last step are all there.  A stale state comes first, in colour on a terminal."""
    st, v, u = board.state, board.verdicts, board.unsafe
    if st is None or v is None or u is None or not st.seq == v.seq == u.seq:
        return []
    out = render(Observed(board.state, board.verdicts, board.unsafe, board.state_space), colour)
    alive = board.alive
    out.append("services  " + ", ".join(f"{s}: {len(alive.get(s, ()))}" for s in ("monitor", "bridge_ros2", "predictor")))
    if not alive.get("monitor"):
        out.append("  NO MONITOR ALIVE: showing its last messages")
    out.append(f"violations ({len(board.violations)})" + "".join(
        f"\n  {v['property']} at step {v['seq']}" + (f" by {v['event']}" if v["event"] else "")
        for v in board.violations[-10:]))
    return out


def _look(board: Board, colour: bool = False) -> tuple[list[str], str, tuple, bool]:
    """(view lines, one-line summary, what changed, prediction fresh and state live) of ``board``."""
    lines = view_lines(board, colour)
    if not lines:
        return [], "", (), False
    line = summary(Observed(board.state, board.verdicts, board.unsafe, board.state_space))  # type: ignore[arg-type]
    sync = tuple((n, s.state) for n, s in board.state.sync.items())  # type: ignore[union-attr]
    key = (board.epoch, board.state.seq, board.unsafe.stamp, sync,  # type: ignore[union-attr]
           board.state_space and board.state_space.stamp,
           tuple(sorted((s, len(ids)) for s, ids in board.alive.items())), len(board.violations))
    fresh = not board.unsafe.prediction_stale and board.state_space is not None and \
        not board.unsafe.state_stale  # type: ignore[union-attr]
    return lines, line, key, fresh


def watch(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Run the view until interrupted or ``--duration``; ``--once`` prints one view (after the
    first fresh prediction, or ``--wait`` seconds) and returns.  Returns the exit status."""
    config = config_from_args(args)
    session = open_session(config)
    changed = threading.Event()
    observer = Observer(session, args.system, client=client_name(config))
    try:
        observer.listen(lambda _updates: changed.set())
        if not observer.wait_monitor(args.wait):
            raise SkinetError(no_monitor_message(session, args.system).replace("; waiting for one", ""))
        stop = stop_on_signals()
        now = time.monotonic()
        end = now + args.wait if args.once else (None if args.duration is None else now + args.duration)
        tty, shown = out.isatty(), None
        while True:
            changed.clear()
            lines, line, key, fresh = observer.read(lambda b: _look(b, tty))  # type: ignore[misc]
            done = stop.is_set() or (end is not None and time.monotonic() >= end)
            if args.once:
                if lines and (fresh or done):
                    print("\n".join(lines), file=out, flush=True)
                    return 0
            elif lines and key != shown:
                out.write(CLEAR + "\n".join(lines) + "\n" if tty else line + "\n")
                out.flush()
                shown = key
            if done:
                return 0
            changed.wait(0.5)
    finally:
        observer.close()
        session.close()
