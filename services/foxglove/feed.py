"""The monitor's results to the Foxglove view of ``skinet run --foxglove``, through a pipe (docs/foxglove.md).

Why not Zenoh: a subscriber of the monitor's keys in another process costs each of the monitor's puts,
whatever it does with the messages (Zenoh sends in the putting thread; benchmarks/bench_latency.py, p99 about
twice the monitor's alone, docs/performance.md).  So ``skinet run`` hands its view process the monitor's
results through a pipe: :class:`PipeFeed` is a tap of the monitor (``Monitor(tap=...)``) and writes each
result message as a frame (kind: 1 byte, length: 4 bytes, the msgpack payload), a step's three in one
non-blocking write made without letting go of the interpreter (``os.write`` lets go, and the monitor's other
threads then kept it from the monitor: p99 +50 µs); :class:`PipeReader`, in the view's process, wakes every
:data:`~services.foxglove.translate.ROUND` while steps come, reads what came and hands it to a fed
:class:`~services.dashboard.observer.Observer`.  While steps come nobody sleeps on the pipe, so a write wakes
nobody: the view reads after the monitor's steps, as a display refreshes.  A round that finds the pipe empty
sleeps on it instead, so the first write after a quiet spell wakes the view once, and an idle view does not
wake 50 times a second.  Pilot statuses and liveliness stay on Zenoh.

The monitor never waits: the feed fills the pipe to a quarter of its size at most (``budget``: 256 KiB of
:data:`PIPE_SIZE`, some 200 steps of the paper's mission at about 1.3 KiB each), so that a write always finds
room and is never cut; a message that would go past it is dropped and counted, a gap mark is written in its
place, and the next ones are dropped too until the reader has emptied the pipe.  To know how full the pipe is,
the feed asks the kernel (``FIONREAD``, through libc's ``ioctl``: ``fcntl.ioctl`` lets go of the interpreter
too) only when what it wrote since it last asked could have reached the budget, or while a gap lasts.  When it
writes again, it first writes the last message of each kind it dropped: the view is back in the present without
asking anything of the monitor.  If the monitor stays quiet for :data:`QUIET` after a gap mark, the reader asks it
for its last results (a Zenoh ``get``; what it reads in the next two rounds may then be older copies).  Only the
log lines of the steps missed are lost (the monitor's list of divergences names each violation's onset, at its
step).  The reader starts by asking the monitor too (it may have published before).  The end of the pipe
(``skinet run`` gone, even killed) ends the view.

The view's own work is about 90 µs of CPU per step: nothing at a robot's pace, most of a core back to back
(about 1 700 steps a second), where it doubled the monitor's p99 on 2 shared cores whatever the view's priority
(``SCHED_IDLE`` measured no better; docs/foxglove.md).  So a round that brings more than
:data:`~services.foxglove.translate.STEPS_PER_ROUND` steps (500 a second; a robot makes a few) hands the observer
only the last of each kind up to its last complete step (the list of divergences first: it names the onset of
every violation at its own step), and the view logs one line saying how many steps it did not show; the step
still incomplete waits for the next round.  While such a flood lasts the rounds come every
:data:`~services.foxglove.translate.FLOOD_ROUND`, and the pipe overflows between them by design: the view's work
is about 4 small rounds a second, whatever the rate.

Cost: one ``write`` system call per step in the monitor's thread (about 2 µs here), and no allocation the
garbage collector tracks; in the view, one ``read`` per round and, past
:data:`~services.foxglove.translate.STEPS_PER_ROUND`, the decoding of five messages per round.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import errno
import fcntl
import logging
import os
import select
import stat
import struct
import termios
import threading
import time

from services.dashboard.observer import MONITOR_RESULTS, Observer
from services.foxglove.translate import FLOOD_ROUND, ROUND, STEPS_PER_ROUND
from skinet.wire.messages import LiveState, Verdicts

HEADER = struct.Struct("<BI")  # kind (an index in MONITOR_RESULTS, or GAP), payload length
GAP = 255
GAP_MARK = HEADER.pack(GAP, 0)
PIPE_SIZE = 1 << 20  # bytes the pipe is asked to hold (Linux's default limit for an unprivileged process)
QUIET = 0.5  # seconds after a gap mark with nothing written, after which the reader asks the monitor
IDLE_LOOK = 1.0  # seconds between the looks of a reader sleeping on an empty pipe at whether the view ended
STATE = [kind for _, kind in MONITOR_RESULTS].index(LiveState)
HELD = frozenset((STATE, [kind for _, kind in MONITOR_RESULTS].index(Verdicts)))  # written with their report
log = logging.getLogger("skinet.foxglove")
_libc = ctypes.PyDLL(None, use_errno=True)  # libc's functions, called without letting go of the interpreter
_write = _libc.write
_write.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_size_t)
_write.restype = ctypes.c_ssize_t
_ioctl = _libc.ioctl  # fcntl.ioctl lets go of it, as os.write does
_ioctl.argtypes = (ctypes.c_int, ctypes.c_ulong, ctypes.c_void_p)
_ioctl.restype = ctypes.c_int


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
        self._asked = ctypes.c_int(0)
        self._gap = False
        self._held: list[bytes] = []  # a step's frames before its report
        self._latest: dict[int, bytes] = {}  # kind -> the last frame dropped in the present gap
        self.sent = 0
        self.dropped = 0
        self.gaps = 0

    def record(self, key: str, payload: bytes, t: float = 0.0) -> None:
        """The monitor's tap: frames ``payload`` when ``key`` is one of the monitor's results (events are not).  A
        step's state and verdicts wait for its report, which the monitor publishes last (``Monitor._publish``):
        one write per step."""
        kind = self._kinds.get(key)
        if kind is None:
            return
        frame = HEADER.pack(kind, len(payload)) + payload
        with self._lock:
            if self._fd < 0:
                return
            self._held.append(frame)
            if kind in HELD:
                return
            count, data = len(self._held), b"".join(self._held)
            try:
                if self._gap or self._bound + len(data) > self.budget:  # else the pipe has room: not asked
                    self._bound = self._unread()
                    if (self._gap and self._bound) or self._bound + len(data) > self.budget:
                        self.dropped += count  # and the next ones, until the reader took all, its gap mark too
                        for dropped in self._held:  # the last of each kind, written when the gap ends
                            self._latest[dropped[0]] = dropped
                        if not self._gap:
                            self._gap = True
                            self.gaps += 1
                            self._send(GAP_MARK)
                        return
                if self._gap:  # the reader took all: the last of each kind dropped, then this, bring the present
                    for frame in self._held:
                        self._latest[frame[0]] = frame
                    count, data = len(self._latest), b"".join(self._latest[k] for k in sorted(self._latest))
                    self._latest.clear()
                    self._gap = False
                self._send(data)
                self.sent += count
            except OSError:  # the view's process is gone (EPIPE): nothing more to write
                self._close()
            finally:
                self._held.clear()

    def _unread(self) -> int:
        """The bytes in the pipe that the reader has not taken (``FIONREAD``), the interpreter held."""
        if _ioctl(self._fd, termios.FIONREAD, ctypes.byref(self._asked)) < 0:
            code = ctypes.get_errno()
            raise OSError(code, os.strerror(code))
        return self._asked.value

    def _send(self, data: bytes) -> None:
        """Write ``data`` whole, the interpreter held (``os.write`` hands it to the monitor's other threads, and
        taking it back cost the monitor's p99 more than the write).  Within the budget (a quarter of the pipe)
        the pipe always has room; were it full anyway, the rest is written waiting for the reader (a cut frame
        would garble every later one)."""
        self._bound += len(data)
        done = _write(self._fd, data, len(data))
        if done < 0:
            code = ctypes.get_errno()
            if code != errno.EAGAIN:
                raise OSError(code, os.strerror(code))
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
    :data:`~services.foxglove.translate.ROUND` while steps come, else when the pipe holds something; sets
    ``ended`` when the pipe's writer is gone or ``observer``'s session closed."""

    def __init__(self, fd: int, observer: Observer, ended: threading.Event):
        self.observer = observer
        self.ended = ended
        self.gaps = 0
        self.messages = 0  # handed to the observer
        self.skipped = 0  # steps not shown: more than STEPS_PER_ROUND in a round
        self.rounds = 0  # reads of the pipe
        self._skipped_seen = 0
        self._round = ROUND  # seconds before this round
        self._fd = fd
        self._kinds = [kind for _, kind in MONITOR_RESULTS]
        self._wake = os.pipe()  # close() writes to it: the thread sleeping on the feed's pipe wakes
        self._poll = select.poll()
        for watched in (fd, self._wake[0]):
            self._poll.register(watched, select.POLLIN)
        self._thread = threading.Thread(target=self._run, name="skinet-foxglove-feed", daemon=True)
        os.set_blocking(fd, False)
        self._thread.start()

    def close(self) -> None:
        self.ended.set()
        with contextlib.suppress(OSError):  # the thread may have closed the other end already
            os.write(self._wake[1], b"x")
        self._thread.join(timeout=5)
        with contextlib.suppress(OSError):  # closed before
            os.close(self._wake[1])

    def _run(self) -> None:
        buffer = b""
        catch_up, older = True, 0  # older: rounds whose messages may be older than the last catch-up's answers
        gap_at: float | None = None  # when the last gap mark was read, until the feed writes again
        try:
            while not self.ended.is_set():
                if catch_up:
                    if not self.observer.fetch_results():
                        return
                    catch_up, older = False, 2  # this round's and the next: written before the answers
                data, end = self._read()
                self.rounds += 1
                buffer += data
                done, gap = self._frames(buffer, older > 0)
                buffer = buffer[done:]
                older = max(older - 1, 0)
                if gap:
                    gap_at = time.monotonic()
                elif done and gap_at is not None:
                    gap_at = None  # the feed wrote the last of each kind it dropped: the present
                elif gap_at is not None and time.monotonic() - gap_at > QUIET:
                    catch_up, gap_at = True, None  # the monitor went quiet meanwhile: ask it
                if end:  # skinet run is over: the view shows what it last had
                    return
                flood, self._skipped_seen = self.skipped != self._skipped_seen, self.skipped
                self._round = FLOOD_ROUND if flood else ROUND
                if data or buffer or gap_at is not None or catch_up:
                    self.ended.wait(self._round)
                else:
                    self._wait_for_data()
        finally:
            os.close(self._fd)
            os.close(self._wake[0])
            self.ended.set()

    def _wait_for_data(self) -> None:
        """Sleep on the pipe until it holds something (or its writer is gone), :meth:`close` wakes the thread,
        or :data:`IDLE_LOOK` passes (``ended`` may be set by another)."""
        while not self.ended.is_set():
            if self._poll.poll(IDLE_LOOK * 1000):  # either of its two pipes
                return

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
        """Hand ``buffer``'s whole frames to the observer, up to a gap mark, all of them or, past
        :data:`~services.foxglove.translate.STEPS_PER_ROUND` steps, the last of each kind (:meth:`_last_of_each`);
        (bytes used, whether a gap came)."""
        frames, used, gap = self._split(buffer)
        states = [i for i, (kind, _, _) in enumerate(frames) if kind == STATE]
        if len(states) > STEPS_PER_ROUND:
            if not gap:  # the last step may lack its verdicts yet: it waits for the next round
                used = frames[states[-1]][1] - HEADER.size
                frames, states = frames[:states[-1]], states[:-1]
            frames = self._last_of_each(frames)
            self.skipped += len(states) - 1
            self.messages += len(frames)
            for kind, start, end in frames:
                self.observer.take(buffer[start:end], self._kinds[kind], older)
            self.observer.note({"kind": "skipped", "steps": len(states) - 1, "most": STEPS_PER_ROUND,
                                "round": self._round})
            return used, gap
        for kind, start, end in frames:
            self.messages += 1
            self.observer.take(buffer[start:end], self._kinds[kind], older)
        return used, gap

    def _split(self, buffer: bytes) -> tuple[list[tuple[int, int, int]], int, bool]:
        """``buffer``'s whole frames up to a gap mark, as (kind, start, end) of their payloads; the bytes they
        take (the gap mark's too), and whether one came."""
        frames: list[tuple[int, int, int]] = []
        at, size = 0, HEADER.size
        while len(buffer) - at >= size:
            kind, length = HEADER.unpack_from(buffer, at)
            if kind == GAP:
                self.gaps += 1
                if self.gaps == 1:
                    log.warning("the Foxglove view fell behind the monitor (its pipe was full): the log lines of "
                                "the steps it missed are not sent")
                return frames, at + size, True
            if len(buffer) - at - size < length:
                break
            frames.append((kind, at + size, at + size + length))
            at += size + length
        return frames, at, False

    @staticmethod
    def _last_of_each(frames: list[tuple[int, int, int]]) -> list[tuple[int, int, int]]:
        """The last frame of each kind, in :data:`MONITOR_RESULTS`' order: the list of divergences first (it
        names the onsets of the violations in the steps not shown, at their own steps), then the last state,
        its verdicts and its report."""
        last = {frame[0]: frame for frame in frames}
        return [last[kind] for kind in sorted(last)]


def pipe_fd(text: str) -> int:
    """``--feed``'s value: the number of a pipe open in this process."""
    try:
        fd = int(text)
        if fd >= 0 and stat.S_ISFIFO(os.fstat(fd).st_mode):
            return fd
    except (ValueError, OSError):
        pass
    raise argparse.ArgumentTypeError(f"expected the number of a pipe open in this process, got '{text}'")
