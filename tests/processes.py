"""Stopping the service processes a test started, and showing what they printed."""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Sequence
from pathlib import Path


def stop_and_show(procs: Sequence[tuple[subprocess.Popen, Path]], tail: int | None = None) -> None:
    """SIGTERM every process still running, wait (SIGKILL after 5 s), then print each log
    (its last ``tail`` characters when given) under the process's module and exit status."""
    for proc, _ in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    for proc, log in procs:
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        text = log.read_text(errors="replace")
        print(f"--- {' '.join(proc.args[2:4])} (exit {proc.returncode}) ---\n{text if tail is None else text[-tail:]}")
