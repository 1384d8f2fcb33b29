"""Starting and stopping the processes of a chain (services, ``skinet`` commands, routers), for the tests and the
benchmarks, and showing what they printed.  Every process starts from the repository root in a session of its
own (a Ctrl-C in the terminal reaches the test runner only); cost: one fork and exec each."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TextIO

REPO = Path(__file__).resolve().parents[1]


def start(argv: Sequence[str], log: Path | TextIO | None = None, env: dict[str, str] | None = None,
          cwd: Path = REPO, pass_fds: Sequence[int] = ()) -> subprocess.Popen:
    """``argv`` as a process: its output (standard error too) appended to the file ``log``, written to the open
    stream ``log``, or, without one, on a text pipe (``proc.stdout``) the caller reads; ``pass_fds``: file
    descriptors it inherits (a pipe's end)."""
    if isinstance(log, Path):
        with log.open("ab") as out:
            return subprocess.Popen(list(argv), cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT,
                                    start_new_session=True, pass_fds=pass_fds)
    if log is not None:
        return subprocess.Popen(list(argv), cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, pass_fds=pass_fds)
    return subprocess.Popen(list(argv), cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True, pass_fds=pass_fds)


def start_module(module: str, *args: str, log: Path | TextIO | None = None,
                 env: dict[str, str] | None = None, pass_fds: Sequence[int] = ()) -> subprocess.Popen:
    """``python -m MODULE ARGS`` (a service: ``services.monitor``, ...), as :func:`start`."""
    return start([sys.executable, "-m", module, *args], log, env, pass_fds=pass_fds)


def run_skinet(*args: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """``skinet ARGS`` run to its end from the repository root, its standard output and error captured as text."""
    return subprocess.run([sys.executable, "-m", "skinet_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=timeout)


def start_skinet(*args: str, log: Path | TextIO | None = None) -> subprocess.Popen:
    """``skinet ARGS``, as :func:`start`."""
    return start_module("skinet_cli.main", *args, log=log)


def stop(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 5.0) -> int:
    """Send ``sig`` unless it ended, wait ``timeout`` seconds (SIGKILL then); its exit status."""
    if proc.poll() is None:
        proc.send_signal(sig)
    return _ended(proc, timeout)


def stop_all(procs: Sequence[subprocess.Popen], timeout: float = 5.0) -> None:
    """SIGTERM every process still running (the last started first), then wait for each (SIGKILL after
    ``timeout`` seconds): they stop together, not one after the other."""
    for proc in reversed(procs):
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    for proc in reversed(procs):
        _ended(proc, timeout)


def _ended(proc: subprocess.Popen, timeout: float) -> int:
    """The exit status once ``proc`` ended, SIGKILLed after ``timeout`` seconds."""
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait(timeout)


def stop_and_show(procs: Sequence[tuple[subprocess.Popen, Path]], tail: int | None = None) -> None:
    """:func:`stop_all`, then print each log (its last ``tail`` characters when given) under the process's
    module and exit status."""
    stop_all([proc for proc, _ in procs])
    for proc, log in procs:
        text = log.read_text(errors="replace")
        print(f"--- {' '.join(proc.args[2:4])} (exit {proc.returncode}) ---\n{text if tail is None else text[-tail:]}")


class Watched:
    """A command's process with its output (standard error too), each line with the seconds since
    start at which it came, collected by a thread."""

    def __init__(self, argv: Sequence[str], cwd: Path = REPO, env: dict[str, str] | None = None):
        self.argv = list(argv)
        self.started = time.monotonic()
        self.proc = start(self.argv, env=env, cwd=cwd)
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
        """SIGTERM (SIGKILL after 30 s); the exit status, once its output was read."""
        stop(self.proc, timeout=30)
        return self.wait(10)
