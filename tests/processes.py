"""Stopping the service processes a test started, and showing what they printed."""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
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


class Watched:
    """A command's process with its output (standard error too), each line with the seconds since
    start at which it came, collected by a thread."""

    def __init__(self, argv: Sequence[str], cwd: Path, env: dict[str, str] | None = None):
        self.argv = list(argv)
        self.started = time.monotonic()
        self.proc = subprocess.Popen(self.argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, start_new_session=True)
        self.timed: list[tuple[float, str]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.timed.append((time.monotonic() - self.started, line.rstrip("\n")))

    @property
    def lines(self) -> list[str]:
        return [line for _, line in self.timed]

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, ready: Callable[[str], bool], what: str, timeout: float = 60.0) -> None:
        """Until ``ready(text)``; fails the test when the process ends first or after ``timeout``."""
        import pytest

        deadline = time.monotonic() + timeout
        while not ready(self.text):
            if self.proc.poll() is not None:
                self._reader.join(5)
                if ready(self.text):
                    return
                pytest.fail(f"{' '.join(self.argv)} exited ({self.proc.returncode}) before {what}:\n{self.text}")
            if time.monotonic() > deadline:
                pytest.fail(f"{' '.join(self.argv)}: not {what} within {timeout} s:\n{self.text}")
            time.sleep(0.05)

    def wait(self, timeout: float = 60.0) -> int:
        """The exit status, once the process ended and its output was read."""
        code = self.proc.wait(timeout)
        self._reader.join(5)
        return code

    def stop(self) -> int:
        """SIGTERM (SIGKILL after 30 s); the exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.wait(10)
