"""Stacks on demand: SIGUSR1 makes a process write every thread's stack and go on (docs/operator.md, "A command
that does not stop").  Standard library only: ``skinet`` imports it at start-up.  Cost: none until the signal.
"""

from __future__ import annotations

import faulthandler
import signal
import sys
import threading


def stacks_on_sigusr1() -> None:
    """From the main thread: SIGUSR1 writes every thread's stack on standard error and the process goes on (what
    to send a hung command or service before killing it)."""
    if threading.current_thread() is threading.main_thread():
        try:
            faulthandler.register(signal.SIGUSR1, file=sys.__stderr__, all_threads=True)
        except (AttributeError, ValueError, OSError):  # no standard error file (embedded, closed)
            pass
