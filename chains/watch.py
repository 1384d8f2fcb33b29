"""``skinet watch SYSTEM_NAME``: the terminal operator view of any running deployment (docs/semantics.md §7).

A read-only observer (:class:`~services.dashboard.observer.Observer`) follows the
monitor's messages through Zenoh; the view is the one ``skinet run`` draws
(:func:`chains.embedded.render`), plus the services alive, the violations
seen and the model divergences and manager restarts of the run (the monitor's list so
far, for a watch that joins late too), and the pilot's status (docs/semantics.md §8: its goal, state, next command):
redrawn in place on a terminal, one line per step otherwise (:class:`StepLines`), one per divergence or
restart and one per change of the pilot's status (as ``skinet goal`` prints them); a
state the monitor cannot vouch for (a skillset syncing or lost, docs/semantics.md §7) is a banner on top,
red or yellow on a terminal, and ``STATE STALE`` in a pipe's line (a skillset lost is a line at
once, one still syncing after a second too).  With no
monitor of the system alive within ``--wait`` seconds it says so, naming the
systems it can see, and exits 1.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections import deque
from typing import TextIO

from services.common.zenoh_config import (
    check_connected, client_name, config_from_args, open_session, said_at_the_end,
)
from services.dashboard.board import Board
from services.dashboard.observer import Observer
from services.dashboard.observer import no_monitor_message
from chains.embedded import CLEAR, Observed, divergence_line, divergence_lines, render, summary
from services.common.cli import stop_on_signals
from chains.replay import INSTANCE_PREFIX as REPLAY
from skinet.errors import SkinetError
from skinet.wire.messages import PilotStatus
from chains.pilot_lines import StatusLines, status_line


def view_lines(board: Board, colour: bool = False) -> list[str]:
    """The operator view of what ``board`` holds; empty until the three messages of the
    monitor's last step are all there.  A stale state comes first, in colour on a terminal."""
    st, v, u = board.state, board.verdicts, board.unsafe
    if st is None or v is None or u is None or not st.seq == v.seq == u.seq:
        return []
    out = render(Observed(board.state, board.verdicts, board.unsafe, board.state_space), colour)
    alive = board.alive
    off = not alive.get("pilot") and board.pilot is None  # never heard of: not started (demo --live), no failure
    out.append("services  " + ", ".join(f"{s}: {'off' if s == 'pilot' and off else len(alive.get(s, ()))}"
                                        for s in ("monitor", "bridge_ros2", "predictor", "pilot")))
    if board.pilot is not None:
        out.append(pilot_line(board.pilot))
    if not alive.get("monitor"):
        out.append("  NO MONITOR ALIVE: showing its last messages")
    elif all(i.startswith(REPLAY) for i in alive["monitor"]):
        out.append("  REPLAY of a recorded run (skinet replay), not the live robot")
    out.append(f"violations ({len(board.violations)})" + "".join(
        f"\n  {v['property']} at step {v['seq']}" + (f" by {v['event']}" if v["event"] else "")
        + (" (already violated when this view joined)" if v.get("joined") else "")
        for v in board.violations[-10:]))
    return out + divergence_lines(list(board.divergences.values()), board.divergences_older)


def pilot_line(status: PilotStatus) -> str:
    """``pilot goal N (MODE, from CLIENT): STATE[: REASON] — ...`` (goal 0: no goal yet)."""
    if status.goal_id == 0:
        return f"pilot     {status.state}" + (f": {status.reason}" if status.reason else "")
    who = f", from {status.client}" if status.client else ""
    return f"pilot     goal {status.goal_id} ({status.mode}{who}): {status_line(status)}"


def _look(board: Board, colour: bool = False) -> tuple[list[str], str, tuple, bool]:
    """(view lines, one-line summary, what changed, prediction fresh and every skillset live) of ``board``;
    what changed starts with (epoch, step, the skillsets not live with their states)."""
    lines = view_lines(board, colour)
    if not lines:
        return [], "", (), False
    line = summary(Observed(board.state, board.verdicts, board.unsafe, board.state_space))  # type: ignore[arg-type]
    sync = tuple((n, s.state) for n, s in board.state.sync.items())  # type: ignore[union-attr]
    stale = tuple((n, state) for n, state in sync if state != "live")
    key = (board.epoch, board.state.seq, stale, board.unsafe.stamp,  # type: ignore[union-attr]
           board.state_space and board.state_space.stamp,
           tuple(sorted((s, len(ids)) for s, ids in board.alive.items())), len(board.violations),
           len(board.divergences) + board.divergences_older, board.pilot and (board.pilot.pilot, board.pilot.seq))
    fresh = not board.unsafe.prediction_stale and board.state_space is not None and \
        not board.unsafe.state_stale  # type: ignore[union-attr]
    return lines, line, key, fresh


class StepLines:
    """One line per monitor step for a pipe: a step's line is written once, when its prediction is
    fresh and every skillset live (or no predictor is alive to make it so), when the next step
    comes, or at the end; the monitor publishes a step several times (its prediction pending, then
    fresh; its sync states changed).  A step whose skillsets are not all live (docs/semantics.md §7) is a line of
    its own per set of sync states: at once when one is lost, after ``settle`` seconds otherwise
    (the seconds' syncing at start is no line), and the step's line is due again once they are
    all live.  A step here is (epoch, seq, the skillsets not live with their states).

    A divergence, restart or violation line names its step: it is written after that step's line
    (the monitor publishes its list and its verdicts on two keys, which may arrive in either order),
    or after ``hold`` seconds if that line does not come."""

    def __init__(self, out: TextIO, settle: float = 1.0, hold: float = 2.0):
        self.out, self.settle, self.hold = out, settle, hold
        self.step: tuple | None = None  # (epoch, seq, states not live) of the step last seen
        self.line = ""
        self.written = True
        self.since = 0.0  # monotonic time the step was first seen
        self.written_seq = -1  # the last step whose line was written
        self.notes: deque[tuple[int | None, str, float]] = deque()  # (step or None, line, monotonic time noted)

    def note(self, seq: int | None, line: str) -> None:
        """A line of its own about step ``seq`` (None: about no step, written at once)."""
        self.notes.append((seq, line, time.monotonic()))

    def see(self, step: tuple, line: str, final: bool) -> None:
        if step != self.step:
            if self.step is None or step[:2] != self.step[:2]:
                self.flush()  # a new step: the last one's line, if not written yet
            self.step, self.written, self.since = step, False, time.monotonic()  # else it was superseded
        self.line = line
        if final:
            self.flush()

    def due(self, now: float) -> None:
        """Write the line of a step whose skillsets have not all been live for ``settle`` seconds, then
        the notes whose step was written or that waited ``hold`` seconds."""
        if self.step is not None and self.step[2] and now - self.since >= self.settle:
            self.flush()
        self._notes(now)

    def flush(self, notes: bool = False) -> None:
        """Write the step's line if not written yet (and every note waiting when ``notes``: the end)."""
        if not self.written:
            self.out.write(self.line + "\n")
            self.written = True
            if self.step is not None:
                self.written_seq = max(self.written_seq, self.step[1])
        self._notes(None if notes else time.monotonic())  # flushes the output

    def _notes(self, now: float | None) -> None:
        while self.notes:
            seq, line, at = self.notes[0]
            if not (now is None or seq is None or seq <= self.written_seq or now - at >= self.hold):
                break  # in order: the later notes wait behind it
            self.out.write(line + "\n")
            self.notes.popleft()
        self.out.flush()


def watch(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Run the view until interrupted or ``--duration``; ``--once`` prints one view (after the
    first fresh prediction, or ``--wait`` seconds) and returns.  Returns the exit status."""
    config = config_from_args(args, command=True)
    session = open_session(config, said_at_the_end)
    changed = threading.Event()
    observer = Observer(session, args.system, client=client_name(config))
    tty = out.isatty()
    seen: deque[tuple[tuple, str, bool]] = deque()  # a pipe's (step, line, final), every update
    noted: deque[tuple[int | None, str]] = deque()  # a pipe's (step, line) of divergences, restarts, pilot changes
    first = [True]  # the first list: a watch that joined late says how many it cannot list
    in_order = threading.Lock()  # the lines of the snapshot before those of later updates
    pilot_lines = StatusLines(say_mode=False)  # a pipe's line per change of the pilot's status

    def pilot(status: PilotStatus | None) -> None:
        if status is not None and pilot_lines.line(status) is not None:
            noted.append((None, pilot_line(status)))

    def note(added: list[dict], older: int) -> None:
        if first[0] and older:
            noted.append((None, f"({older} earlier divergences and manager restarts not listed)"))
        first[0] = False
        noted.extend((d["seq"], divergence_line(d, loud=True)) for d in added)

    def on_update(updates: list[dict]) -> None:  # on Zenoh's thread, the observer's lock held
        if not tty and not args.once:
            with in_order:
                for u in updates:
                    if u["kind"] == "divergences":
                        note(u["added"], u["older"])
                    elif u["kind"] == "pilot":
                        pilot(observer.board.pilot)
            lines, line, key, fresh = _look(observer.board)
            if lines:
                live = not observer.board.unsafe.state_stale
                lost = any(state == "lost" for _, state in key[2])
                final = lost or fresh or (live and not observer.board.alive.get("predictor"))
                seen.append((key[:3], line, final))
        changed.set()

    try:
        with in_order:
            start = observer.listen(on_update)
            if not tty and not args.once and (start["divergences"] or start["divergences_older"]):
                note(start["divergences"], start["divergences_older"])  # what the observer got before we listened
            if not tty and not args.once:
                pilot(observer.board.pilot)
        if not observer.wait_monitor(args.wait):
            check_connected(session, config)
            raise SkinetError(no_monitor_message(session, args.system, config).replace("; waiting for one", ""))
        stop = stop_on_signals()
        now = time.monotonic()
        end = now + args.wait if args.once else (None if args.duration is None else now + args.duration)
        shown = None
        steps = StepLines(out)
        while True:
            changed.clear()
            lines, line, key, fresh = observer.read(lambda b: _look(b, tty))  # type: ignore[misc]
            done = stop.is_set() or (end is not None and time.monotonic() >= end)
            if args.once:  # after the first fetch: its list holds what happened before this view joined
                if lines and (fresh and observer.fetched.is_set() or done):
                    print("\n".join(lines), file=out, flush=True)
                    return 0
            elif tty and lines and key != shown:
                out.write(CLEAR + "\n".join(lines) + "\n")
                out.flush()
                shown = key
            while seen:
                steps.see(*seen.popleft())
            while noted:
                steps.note(*noted.popleft())
            steps.due(time.monotonic())
            if done:
                steps.flush(notes=True)
                return 0
            changed.wait(0.5)
    finally:
        observer.close()
        session.close()
