"""The monitor's results to the Foxglove view of ``skinet run --foxglove``, through a pipe (docs/foxglove.md).

Why not Zenoh: a subscriber of the monitor's keys in another process costs each of the monitor's puts,
whatever it does with the messages (Zenoh sends in the putting thread; benchmarks/bench_latency.py, p99 about
twice the monitor's alone, docs/performance.md).  So ``skinet run`` hands its view process the monitor's
results through a pipe: :class:`PipeFeed` is a tap of the monitor (``Monitor(tap=...)``) and writes each
result message as a frame (kind: 1 byte, length: 4 bytes, the msgpack payload) with one non-blocking write;
:class:`PipeReader`, in the view's process, wakes every :data:`ROUND`, reads what came and hands it to a fed
:class:`~services.dashboard.observer.Observer`.  Nobody sleeps on the pipe, so a write wakes nobody: the view
reads after the monitor's steps, as a display refreshes.  Pilot statuses and liveliness stay on Zenoh.

The monitor never waits: the feed fills the pipe to a quarter of its size at most (``budget``: 256 KiB of
:data:`PIPE_SIZE`, some 200 steps of the paper's mission at about 1.3 KiB each), so that a write always finds
room and is never cut; a message that would go past it is dropped and counted, a gap mark is written in its
place, and the next ones are dropped too until the reader has emptied the pipe (one catch-up per gap, however
far behind the view is).  To know how full the pipe is, the feed asks the kernel (``FIONREAD``) only when what
it wrote since it last asked could have reached the budget, or while a gap lasts.  On a gap mark the reader
asks the monitor for its last results (a Zenoh ``get``) and takes what it reads until the next round as
possibly older copies; the view then shows the present again, and only the log lines of the steps it missed
are lost (the monitor's list of divergences names each violation's onset, so none is lost).  The reader starts
with such a catch-up too (the monitor may have published before it).  The end of the pipe (``skinet run``
gone, even killed) ends the view.

The view's own work stays: about 90 µs of CPU per step.  At a robot's pace that is nothing; back to back (about
1 700 steps a second) it is most of a core, and on 2 shared cores it doubles the monitor's p99 whatever the
view's priority (``SCHED_IDLE`` measured no better; docs/foxglove.md).

Cost: one ``write`` system call per result message in the monitor's thread (about 1.3 µs here), and no
allocation the garbage collector tracks; in the view, one ``read`` per round.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import logging
import os
import stat
import struct
import sys
import termios
import threading

from services.dashboard.observer import MONITOR_RESULTS, Observer

HEADER = struct.Struct("<BI")  # kind (an index in MONITOR_RESULTS, or GAP), payload length
GAP = 255
GAP_MARK = HEADER.pack(GAP, 0)
PIPE_SIZE = 1 << 20  # bytes the pipe is asked to hold (Linux's default limit for an unprivileged process)
ROUND = 0.02  # seconds between the reader's rounds
log = logging.getLogger("skinet.foxglove")


class PipeFeed:
    """Writes the monitor's result messages of ``system`` to the pipe ``fd`` (which it owns): :meth:`record` is
    the monitor's tap."""

    def __init__(self, system: str, fd: int):
        self._fd = fd
        self._kinds = {key(system): i for i, (key, _) in enumerate(MONITOR_RESULTS)}
        self._lock = threading.Lock()  # the monitor's event thread and its prediction replies both write
        os.set_blocking(fd, False)
        with contextlib.suppress(OSError):  # a smaller pipe only fills sooner
            fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, PIPE_SIZE)
        self.budget = fcntl.fcntl(fd, fcntl.F_GETPIPE_SZ) // 4  # bytes the pipe is filled to, at most
        self._bound = 0  # bytes the pipe holds now, at most: what it held when last asked, plus what came since
        self._asked = bytearray(4)
        self._gap = False
        self.sent = 0
        self.dropped = 0
        self.gaps = 0

    def record(self, key: str, payload: bytes, t: float = 0.0) -> None:
        """The monitor's tap: frames ``payload`` when ``key`` is one of the monitor's results (events are not)."""
        kind = self._kinds.get(key)
        if kind is None:
            return
        frame = HEADER.pack(kind, len(payload)) + payload
        with self._lock:
            if self._fd < 0:
                return
            try:
                if self._gap or self._bound + len(frame) > self.budget:  # else the pipe has room: not asked
                    fcntl.ioctl(self._fd, termios.FIONREAD, self._asked)
                    self._bound = int.from_bytes(self._asked, sys.byteorder)
                    if (self._gap and self._bound) or self._bound + len(frame) > self.budget:
                        self.dropped += 1  # and the next ones, until the reader took all, its gap mark too
                        if not self._gap:
                            self._gap = True
                            self.gaps += 1
                            self._send(GAP_MARK)
                        return
                self._gap = False
                self._send(frame)
                self.sent += 1
            except OSError:  # the view's process is gone (EPIPE): nothing more to write
                self._close()

    def _send(self, data: bytes) -> None:
        """Write ``data`` whole.  Within the budget (a quarter of the pipe) the pipe always has room; were it full
        anyway, the rest is written waiting for the reader (a cut frame would garble every later one)."""
        self._bound += len(data)
        try:
            done = os.write(self._fd, data)
        except BlockingIOError:
            done = 0
        if done < len(data):
            os.set_blocking(self._fd, True)
            try:
                while done < len(data):
                    done += os.write(self._fd, data[done:])
            finally:
                os.set_blocking(self._fd, False)

    def close(self) -> None:
        """Close the pipe: the view's reader sees its end."""
        with self._lock:
            self._close()

    def _close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class PipeReader:
    """Feeds ``observer`` (made with ``fed=True``) from the pipe ``fd`` in a thread of its own, every
    :data:`ROUND`; sets ``ended`` when the pipe's writer is gone or ``observer``'s session closed."""

    def __init__(self, fd: int, observer: Observer, ended: threading.Event):
        self.observer = observer
        self.ended = ended
        self.gaps = 0
        self.messages = 0
        self._fd = fd
        self._kinds = [kind for _, kind in MONITOR_RESULTS]
        self._thread = threading.Thread(target=self._run, name="skinet-foxglove-feed", daemon=True)
        os.set_blocking(fd, False)
        self._thread.start()

    def close(self) -> None:
        self.ended.set()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        buffer = b""
        catch_up, older = True, 0  # older: rounds whose messages may be older than the last catch-up's answers
        try:
            while not self.ended.is_set():
                if catch_up:
                    if not self.observer.fetch_results():
                        return
                    catch_up, older = False, 2  # this round's and the next: written before the answers
                data, end = self._read()
                buffer += data
                done, catch_up = self._frames(buffer, older > 0)
                buffer = buffer[done:]
                older = max(older - 1, 0)
                if end:  # skinet run is over: the view shows what it last had
                    return
                self.ended.wait(ROUND)
        finally:
            os.close(self._fd)
            self.ended.set()

    def _read(self) -> tuple[bytes, bool]:
        """What the pipe holds now, and whether its writer is gone."""
        chunks = []
        while True:
            try:
                chunk = os.read(self._fd, PIPE_SIZE)
            except BlockingIOError:
                return b"".join(chunks), False
            if not chunk:
                return b"".join(chunks), True
            chunks.append(chunk)

    def _frames(self, buffer: bytes, older: bool) -> tuple[int, bool]:
        """Hand ``buffer``'s whole frames to the observer, up to a gap mark; (bytes used, whether a gap came)."""
        at, size = 0, HEADER.size
        while len(buffer) - at >= size:
            kind, length = HEADER.unpack_from(buffer, at)
            if kind == GAP:
                self.gaps += 1
                if self.gaps == 1:
                    log.warning("the Foxglove view fell behind the monitor (its pipe was full): it catches up from "
                                "the monitor's last results; the log lines of the steps in between are not sent")
                return at + size, True
            if len(buffer) - at - size < length:
                break
            self.messages += 1
            self.observer.take(buffer[at + size:at + size + length], self._kinds[kind], older)
            at += size + length
        return at, False


def pipe_fd(text: str) -> int:
    """``--feed``'s value: the number of a pipe open in this process."""
    try:
        fd = int(text)
        if fd >= 0 and stat.S_ISFIFO(os.fstat(fd).st_mode):
            return fd
    except (ValueError, OSError):
        pass
    raise argparse.ArgumentTypeError(f"expected the number of a pipe open in this process, got '{text}'")
