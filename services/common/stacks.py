"""Stacks on demand: SIGUSR1 makes a process write every thread's stack and go on (docs/operator.md, "A command
that does not stop").  Standard library only: ``skinet`` imports it at start-up.  Cost: none until the signal.

The stacks are written by a Python-level handler, which runs in the main thread with the interpreter held, so
no other thread changes its frames while they are read.  ``faulthandler.register`` writes them from the C
handler at once, whatever the other threads do: a full run saw it kill a monitor (SIGSEGV) that was logging.
"""

from __future__ import annotations

import faulthandler
import signal
import sys
import threading
from types import FrameType


def _write_stacks(signum: int, frame: FrameType | None) -> None:
    try:
        faulthandler.dump_traceback(file=sys.__stderr__, all_threads=True)
    except (AttributeError, ValueError, OSError):  # no standard error file (embedded, closed)
        pass


def stacks_on_sigusr1() -> None:
    """From the main thread: SIGUSR1 writes every thread's stack on standard error and the process goes on (what
    to send a hung command or service before killing it)."""
    if threading.current_thread() is threading.main_thread():
        try:
            signal.signal(signal.SIGUSR1, _write_stacks)
        except (AttributeError, ValueError, OSError):  # no SIGUSR1 (not POSIX)
            pass
