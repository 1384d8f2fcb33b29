"""Forecasts of untrusted models in a child process with hard limits (docs/semantics.md §6, §7).

A model bundle comes from whoever answered ``skinet/<system>/model/<digest>``: its
digest proves it is consistent, not who wrote it, and a 2 KB skillset whose guards
expand exponentially (docs/semantics.md §3, DNF) can take gigabytes and minutes to build and
explore.  So the predictor never builds or explores in its own process: a
:class:`Worker` runs ``python -m services.predictor.sandbox`` with an address-space
limit (``RLIMIT_AS``) and a lower CPU priority, sends it one job at a time over a
pipe and kills it when the job's deadline (the request's budget plus a grace)
passes.  Net construction, exploration and the reply's risks all happen in the
child, within the request's budget; the parent only moves bytes, so a monitor in
the same process (embedded ``skinet run``) keeps its latency.  A killed child is
replaced at once and its replacement's start-up does not count against the next
job.  Each child keeps the systems it built in a small LRU cache.

Frames on the pipes are a 4-byte big-endian length and a msgpack array: jobs
``[digest, bundle, request, budget, memory_limit]`` (the encoded ModelBundle and
PredictRequest; the core's memory limit in bytes, or None),
answers ``[ok, error, reply]`` (the encoded PredictReply, or a one-line error).
Cost per job in the parent: copying the bundle and the reply through a pipe.
"""

from __future__ import annotations

import argparse
import logging
import os
import select
import signal
import struct
import subprocess
import sys
import time
from collections import OrderedDict
from typing import BinaryIO

import msgpack

log = logging.getLogger("skinet.predictor")

_HEADER = struct.Struct(">I")
READY = b"ready"
MAX_ANSWER = 64 << 20  # an answer larger than this is a bug or an attack: the worker is replaced
EXIT_MEMORY = 3  # the child's exit status after a MemoryError


class WorkerError(Exception):
    """The job did not complete within the worker's limits (one line)."""


class Worker:
    """One child process computing forecasts under a memory limit and per-job deadlines."""

    def __init__(self, instance_id: str, *, memory_mb: int = 2048, cache_size: int = 4, nice: int = 5,
                 startup_timeout: float = 30.0):
        self.instance_id, self.memory_mb, self.cache_size, self.nice = instance_id, memory_mb, cache_size, nice
        self.startup_timeout = startup_timeout
        self.killed = 0  # children killed at a deadline or lost at the memory limit
        self._proc: subprocess.Popen[bytes] | None = None
        self._ready = False
        self._closed = False
        self._spawn()

    def _spawn(self) -> None:
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "services.predictor.sandbox", "--instance", self.instance_id,
             "--memory-mb", str(self.memory_mb), "--cache", str(self.cache_size), "--nice", str(self.nice)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, close_fds=True)
        self._ready = False

    def run(self, digest: str, bundle: bytes, request: bytes, budget: float, grace: float = 1.0,
            memory_limit: int | None = None) -> bytes:
        """The encoded PredictReply of one job; raises :class:`WorkerError` at a limit."""
        proc = self.wait_ready()
        deadline = time.monotonic() + budget + grace
        try:
            _write_frame(proc.stdin, msgpack.packb([digest, bundle, request, budget, memory_limit]))  # type: ignore[arg-type]
            frame = _read_frame(proc.stdout, deadline)  # type: ignore[arg-type]
        except (BrokenPipeError, OSError):
            frame = None
        if frame is None:
            self._replace()
            status = proc.returncode
            if self._closed:
                raise WorkerError("predictor shutting down")
            if status is None or status == -signal.SIGKILL:
                raise WorkerError(f"exceeded the budget of {budget:g} s (+{grace:g} s grace): worker killed")
            if status == EXIT_MEMORY:
                raise WorkerError(f"exceeded the memory limit of {self.memory_mb} MB: worker replaced")
            raise WorkerError(f"worker died (exit status {status}): replaced")
        ok, error, reply = msgpack.unpackb(frame)
        if not ok:
            raise WorkerError(error)
        return reply

    def wait_ready(self) -> subprocess.Popen[bytes]:
        """The child once it has loaded its imports (its start-up counts against no job)."""
        proc = self._proc
        if proc is None:
            raise WorkerError("predictor shutting down")
        if not self._ready:
            if _read_frame(proc.stdout, time.monotonic() + self.startup_timeout) != READY:  # type: ignore[arg-type]
                self._replace()
                if self._closed:
                    raise WorkerError("predictor shutting down")
                raise WorkerError(f"worker did not start (exit status {proc.returncode})")
            self._ready = True
        return proc

    def _replace(self) -> None:
        self.killed += 1
        self._kill()
        if not self._closed:
            self._spawn()

    def _kill(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        for pipe in (proc.stdin, proc.stdout):
            try:
                pipe.close()  # type: ignore[union-attr]
            except OSError:
                pass

    def close(self) -> None:
        """Kill the child at once (a job in progress fails with ``WorkerError``)."""
        self._closed = True
        self._kill()


def _write_frame(pipe: BinaryIO, data: bytes) -> None:
    pipe.write(_HEADER.pack(len(data)) + data)
    pipe.flush()


def _read_exact(fd: int, n: int, deadline: float | None) -> bytes | None:
    chunks, left = [], n
    while left:
        if deadline is not None:
            wait = deadline - time.monotonic()
            if wait <= 0 or not select.select([fd], [], [], wait)[0]:
                return None
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _read_frame(pipe: BinaryIO, deadline: float | None) -> bytes | None:
    """One frame, or None at EOF or past ``deadline`` (monotonic)."""
    fd = pipe.fileno()
    header = _read_exact(fd, _HEADER.size, deadline)
    if header is None:
        return None
    (size,) = _HEADER.unpack(header)
    if size > MAX_ANSWER:
        return None
    return _read_exact(fd, size, deadline)


# -- the child ------------------------------------------------------------------------


WARM_UP = "skillset w{resource{r{state{a b}initial a transition all}}skill k{precondition{p:r==a}start{r->b}}}"


def _serve(instance: str, cache_size: int, nice: int) -> None:
    """Answer jobs from stdin until EOF.

    Before announcing itself the child answers a tiny job, so that imports and the
    parser's grammar are loaded before any deadline runs.
    """
    # scipy too, although the warm-up job's graphs are too small to need it (skinet/verify/scc.py):
    # a worker serves every size of system, and its answers use scipy's strong components throughout.
    import scipy.sparse.csgraph  # noqa: F401

    from skinet.errors import SkinetError
    from skinet.system.model import System
    from skinet.verify.predict import forecast
    from skinet.wire.codec import DecodeError, decode, encode
    from skinet.wire.convert import bundle as bundle_of
    from skinet.wire.convert import (
        bundle_digest, marking_of, request_options, risks, state_space_report, system_from_bundle,
    )
    from skinet.wire.messages import ModelBundle, PredictReply, PredictRequest

    cache: OrderedDict[str, System] = OrderedDict()

    def job(digest: str, bundle: bytes, payload: bytes, budget: float, memory_limit: int | None = None) -> list:
        started = time.perf_counter()
        try:
            request = decode(payload, PredictRequest)
            system = cache.get(digest)
            if system is None:
                system = system_from_bundle(decode(bundle, ModelBundle))
                got = bundle_of(system).digest
                if got != digest:
                    raise DecodeError(f"bundle rebuilds to digest {got}, not {digest}")
                cache[digest] = system
                while len(cache) > cache_size:
                    cache.popitem(last=False)
            cache.move_to_end(digest)
            marking = marking_of(system, request.skillsets, "request")
            left = max(0.0, budget - (time.perf_counter() - started))  # building counts against the budget
            limit = {} if memory_limit is None else {"memory_limit": memory_limit}
            fc = forecast(system, marking, budget=left, options=request_options(system, request), **limit)
            reply = PredictReply(system=request.system, digest=digest, seq=request.seq, ok=True, instance=instance,
                                 report=state_space_report(system, fc, time.time()), risks=risks(system, marking, fc))
            return [True, "", encode(reply)]
        except (SkinetError, DecodeError) as exc:
            return [False, str(exc), b""]
        except MemoryError:
            raise
        except Exception as exc:  # a bug or a pathological model: report it, keep serving
            return [False, f"{type(exc).__name__}: {exc}", b""]

    warm = ModelBundle(system="w", digest="", skillsets=[("w.rl", WARM_UP, "/w")],
                       properties="p = not (w:b and w:i_k)\n", properties_name="w.props")
    warm_digest = bundle_digest(warm)
    ok, error, _ = job(warm_digest, encode(warm), encode(PredictRequest(
        system="w", digest=warm_digest, seq=0, skillsets={}, budget=1.0)), 1.0)
    if not ok:
        raise RuntimeError(f"warm-up job failed: {error}")
    cache.clear()
    if nice:
        os.nice(nice)  # after start-up: a replacement must be ready soon, jobs must yield to the monitor
    out, inp = sys.stdout.buffer, sys.stdin.buffer
    _write_frame(out, READY)
    while (frame := _read_frame(inp, None)) is not None:
        _write_frame(out, msgpack.packb(job(*msgpack.unpackb(frame))))


def _die_with_parent() -> None:
    """Linux: SIGKILL when the parent dies, even one killed by SIGKILL (busy jobs never read EOF)."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux: the child stops at its next job's EOF


def main(argv: list[str] | None = None) -> int:
    import resource

    parser = argparse.ArgumentParser(prog="python -m services.predictor.sandbox",
                                     description="A predictor's worker process (started by the predictor; "
                                                 "reads jobs on stdin, answers on stdout).")
    parser.add_argument("--instance", required=True, help="predictor instance id, copied into replies")
    parser.add_argument("--memory-mb", type=int, default=2048, help="address-space limit, MB (default: 2048)")
    parser.add_argument("--cache", type=int, default=4, help="systems kept (default: 4)")
    parser.add_argument("--nice", type=int, default=5, help="added niceness (default: 5)")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when we stop (Ctrl-C reaches the group)
    _die_with_parent()
    limit = args.memory_mb << 20
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    try:
        _serve(args.instance, args.cache, args.nice)
    except MemoryError:
        os._exit(EXIT_MEMORY)
    except BrokenPipeError:
        pass  # the parent went away
    return 0


if __name__ == "__main__":
    sys.exit(main())
