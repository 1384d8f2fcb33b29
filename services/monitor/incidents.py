"""``--incidents DIR``: incident bundles written around each incident of a live run (docs/foxglove.md).

:class:`Incidents` keeps a ring of the last ``window`` seconds of raw payloads
(key, bytes, receive time), at most :data:`MAX_ENTRIES` of them: the monitor
hands it each event it receives and each message it publishes (:meth:`Incidents.record`
is its ``tap``, called in the monitor's threads after the step's puts, with each message's time), and a
subscriber of the session adds the pilots' statuses.  An incident is a property
going from holding to failing (``Verdicts``), a new model divergence or manager
restart (``Divergences``), or the pilot failing (``PilotStatus``).  ``window``
seconds after the first incident, a bundle of the ring from ``window`` seconds
before it to then is written by :class:`~services.foxglove.bundle.BundleSink`
in its own thread (incidents in between go in the same bundle); written and
failed bundles are counted and logged, never raised.  Cost on the event path:
three bounded deque appends per message, after the step's puts, and no object the
garbage collector tracks; a verdicts payload is searched for a failing property
(read in full only when it holds one), divergence lists and pilot statuses are
decoded at once (the rest when a bundle is written).  No thread of this writer runs Python while
no incident is pending: a ring drained by a thread of its own kept the monitor
from the interpreter for up to Python's 5 ms switch interval (docs/performance.md).  Memory:
at most :data:`MAX_ENTRIES` payloads (each under the codec's size limit;
about 1 KB for the paper's system), whatever the window.  Disk: a bundle is
written under a hidden ``.partial`` name and renamed when complete (a failed
one is removed), then the folder is capped: the oldest bundles of the system
go first until at most ``max_files`` of them and ``max_bytes`` remain (the
newest always stays); the cap costs one listing of the folder per bundle.
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import threading
import time
from collections import deque
from pathlib import Path

import msgpack
import zenoh

from services.common.memory import memory_size
from services.common.options import count
from services.common.zenoh_config import undeclare
from services.foxglove.bundle import BundleSink
from skinet.errors import SkinetError
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.convert import bundle
from skinet.wire.codec import DecodeError, decode
from skinet.wire.messages import (
    CanonicalEvent, Divergences, LiveState, ModelBundle, PilotStatus, StateSpaceReport, UnsafeReport, Verdicts,
)

RECORDED = {"events": CanonicalEvent, "state": LiveState, "verdicts": Verdicts, "unsafe": UnsafeReport,
            "state_space": StateSpaceReport, "divergences": Divergences, "pilot": PilotStatus}
MAX_ENTRIES = 100_000  # payloads kept in the ring, whatever the window
MAX_KEYS = 1024  # keys whose kind is remembered
# A property that fails, as msgpack packs it (a fixstr key, then false): a Verdicts payload without these bytes has
# every property holding.  A string that happens to hold them only costs a full read of the payload.
HOLDS_FALSE = b"\xa5holds\xc2"
MAX_FILES = 100  # default --incidents-max-files
MAX_BYTES = 1 << 30  # default --incidents-max-bytes (1 GiB)
PARTIAL = ".partial"  # suffix of a bundle being written (hidden: its name starts with a dot)
log = logging.getLogger("skinet.incidents")


def _kind(key: str) -> str:
    """The kind of message a key of the system carries (``skinet/<system>/<kind>/...``)."""
    parts = key.split("/")
    return parts[2] if len(parts) > 2 else ""


def _verdict_holds(payload: bytes) -> tuple[int, dict[str, bool]]:
    """A ``Verdicts`` payload's step and ``holds`` per property, without validating the whole message;
    :class:`DecodeError` for what is not one (cost: one msgpack unpack)."""
    try:
        data = msgpack.unpackb(payload, raw=False)
        holds = {p["name"]: bool(p["holds"]) for p in data["properties"]}
        return int(data["seq"]), holds
    except Exception:  # msgpack and a malformed map raise several unrelated types
        raise DecodeError("not a Verdicts payload") from None


class Incidents:
    """Writes incident bundles of ``model``'s system into ``folder``."""

    def __init__(self, session: zenoh.Session, model: ModelBundle, folder: Path, window: float = 30.0,
                 max_files: int = MAX_FILES, max_bytes: int = MAX_BYTES):
        self.model, self.folder, self.window = model, Path(folder), window
        self.max_files, self.max_bytes = max_files, max_bytes
        self.folder.mkdir(parents=True, exist_ok=True)
        self.system = model.system
        self.written: list[Path] = []
        self.removed: list[Path] = []  # bundles the cap removed, oldest first
        self.failed = 0
        self._name = re.compile(re.escape(self.system) + r"-\d{8}-\d{6}-\d{3}\.mcap")
        self._leftovers()
        self._cap()
        # The ring as three deques, not one of tuples: appending a str, a bytes and a float allocates nothing the
        # garbage collector tracks, so the ring adds no collection to the monitor's thread (a tuple per message did:
        # +10 % on the event path's p99, docs/performance.md).
        self._keys: deque[str] = deque(maxlen=MAX_ENTRIES)
        self._payloads: deque[bytes] = deque(maxlen=MAX_ENTRIES)
        self._times: deque[float] = deque(maxlen=MAX_ENTRIES)
        self._kinds: dict[str, str] = {}  # key -> kind, for the few keys of the system
        self._lock = threading.Lock()
        self._holds: dict[str, bool] = {}
        self._noted: dict[str, int] = {}  # monitor run -> divergences noted
        self._pilot_failed: tuple[str, int] | None = None
        self._pending: tuple[float, list[str]] | None = None  # (first incident's time, what happened)
        self._wake = threading.Event()
        self._closed = False
        self._sub = session.declare_subscriber(keys.pilot_status(self.system), self._on_pilot)
        self._thread = threading.Thread(target=self._run, name="skinet-incidents", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop; a pending incident is written with what the ring holds now."""
        undeclare(self._sub)
        self._closed = True
        self._wake.set()
        self._thread.join(timeout=30)

    # -- the ring: O(1) unless the message may be an incident --------------------------------

    def record(self, key: str, payload: bytes, t: float) -> None:
        """Keep one message of the run received or published at wall time ``t`` (the monitor's tap: an event it
        received, after its step's messages, or a message it published)."""
        kind = self._kinds.get(key)
        if kind is None:
            kind = _kind(key)
            if len(self._kinds) < MAX_KEYS:
                self._kinds[key] = kind
        with self._lock:
            self._keys.append(key)
            self._payloads.append(payload)
            self._times.append(t)
            cutoff = t - self.window - 1.0
            while self._times and self._times[0] < cutoff and self._pending is None:
                self._keys.popleft()
                self._payloads.popleft()
                self._times.popleft()
        what = self._incident(kind, payload)
        if what:
            with self._lock:
                if self._pending is None:
                    self._pending = (t, [what])
                else:
                    self._pending[1].append(what)
            self._wake.set()

    def _on_pilot(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self.record(str(sample.key_expr), sample.payload.to_bytes(), time.time())

    def _incident(self, kind: str, payload: bytes) -> str | None:
        try:
            if kind == "verdicts":  # every step: read as plain msgpack (a model's validation costs more)
                if HOLDS_FALSE not in payload:  # every property holds (no allocation: see HOLDS_FALSE)
                    self._holds = {}
                    return None
                seq, holds = _verdict_holds(payload)
                onsets = [name for name, ok in holds.items() if not ok and self._holds.get(name, True)]
                self._holds = holds
                return f"violation of {', '.join(onsets)} at step {seq}" if onsets else None
            if kind == "divergences":
                d = decode(payload, Divergences)
                noted = d.older + len(d.entries)
                before = self._noted.get(d.monitor, 0)
                self._noted[d.monitor] = max(before, noted)
                # Violation onsets are listed too (for views that join later): the verdicts report them.
                kinds = sorted({e.kind for e in d.entries if e.n >= before and e.kind != "violation"})
                if noted > before and (kinds or not d.entries):
                    return " and ".join("manager restart" if k == "restart" else "model divergence"
                                        for k in kinds or ["divergence"])
                return None
            if kind == "pilot":
                p = decode(payload, PilotStatus)
                if p.state == "failed" and self._pilot_failed != (p.pilot, p.goal_id):
                    self._pilot_failed = (p.pilot, p.goal_id)
                    return f"pilot failed goal {p.goal_id}: {p.reason}"
        except DecodeError:
            return None
        return None

    # -- the writer's thread -----------------------------------------------------------------

    def _run(self) -> None:
        while True:
            with self._lock:
                pending = self._pending
            wait = None if pending is None else max(0.0, pending[0] + self.window - time.time())
            if not self._closed and (pending is None or wait):
                self._wake.wait(wait)
                self._wake.clear()
                continue
            if pending is not None:
                self._write(pending[0], pending[1])
            if self._closed:
                return

    def _write(self, t0: float, what: list[str]) -> None:
        with self._lock:
            entries = [e for e in zip(self._keys, self._payloads, self._times) if e[2] >= t0 - self.window]
            self._pending = None
        entries.sort(key=lambda e: e[2])  # an event comes to the ring after its step's messages
        stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(t0))
        path = self.folder / f"{self.system}-{stamp}-{int(t0 * 1000) % 1000:03d}.mcap"
        partial = path.with_name(f".{path.name}{PARTIAL}")
        kept = 0
        try:
            with partial.open("wb") as out:
                sink = BundleSink(out, self.system, trigger="; ".join(what))
                sink.write(keys.model(self.system, self.model.digest), self.model, t0)
                for key, payload, t in entries:
                    kind = RECORDED.get(_kind(key))
                    if kind is None or (kind is PilotStatus and not key.endswith("/status")):
                        continue
                    try:
                        sink.write(key, decode(payload, kind), t)
                        kept += 1
                    except DecodeError:
                        continue
                sink.close()
            os.replace(partial, path)
        except Exception as exc:  # a full disk, a folder removed: counted and logged, the monitor goes on
            self.failed += 1
            try:
                partial.unlink(missing_ok=True)  # never a partial bundle left
            except OSError:
                pass
            log.error("cannot write the incident bundle %s: %s", path, exc)
            return
        log.warning("incident (%s): bundle %s written, %d messages from %g s before to %g s after",
                    "; ".join(what), path, kept, self.window, self.window)
        self._cap()
        self.written.append(path)

    # -- the folder's cap ------------------------------------------------------------------

    def _leftovers(self) -> None:
        """Remove the partial bundles of this system a killed writer left."""
        try:
            for p in self.folder.iterdir():
                if p.name.startswith(".") and p.name.endswith(PARTIAL) and \
                        self._name.fullmatch(p.name[1:-len(PARTIAL)]):
                    p.unlink(missing_ok=True)
        except OSError as exc:
            log.error("cannot remove partial incident bundles in %s: %s", self.folder, exc)

    def _cap(self) -> None:
        """Remove this system's oldest bundles until at most ``max_files`` and ``max_bytes`` remain; the newest
        stays, even alone over ``max_bytes``.  Other files in the folder are never touched."""
        try:
            found = []
            for p in self.folder.iterdir():
                if self._name.fullmatch(p.name):
                    st = p.stat()
                    found.append((st.st_mtime_ns, p.name, st.st_size, p))
        except OSError as exc:
            log.error("cannot list the incident bundles in %s: %s", self.folder, exc)
            return
        found.sort()
        count, total = len(found), sum(size for _, _, size, _ in found)
        for _, _, size, p in found[:-1]:
            if count <= self.max_files and total <= self.max_bytes:
                break
            try:
                p.unlink(missing_ok=True)
            except OSError as exc:
                log.error("cannot remove the incident bundle %s: %s", p, exc)
                continue
            count, total = count - 1, total - size
            self.removed.append(p)
            log.info("incident bundle %s removed: the folder keeps at most %d bundles and %d bytes of %s",
                     p, self.max_files, self.max_bytes, self.system)


def add_incidents_args(p: argparse.ArgumentParser) -> None:
    """``--incidents DIR``, ``--incident-window S`` and the folder's cap, ``--incidents-max-files N`` and
    ``--incidents-max-bytes SIZE``."""
    p.add_argument("--incidents", metavar="DIR",
                   help="write an incident bundle (MCAP; skinet replay FILE --verify re-runs it) into DIR around each "
                        "violation, model divergence, manager restart or pilot failure: the --incident-window "
                        "seconds before and after it")
    p.add_argument("--incident-window", type=_window, default=30.0, metavar="S",
                   help="seconds kept before an incident and recorded after it (default: 30)")
    p.add_argument("--incidents-max-files", type=count(1), default=MAX_FILES, metavar="N",
                   help=f"keep at most N bundles of the system in DIR: the oldest are removed first, the newest "
                        f"always stays (default: {MAX_FILES})")
    p.add_argument("--incidents-max-bytes", type=memory_size, default=MAX_BYTES, metavar="SIZE",
                   help="and at most SIZE bytes of them, e.g. 500MiB (default: 1GiB)")


def _window(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 < value <= 3600:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number of seconds from 0 (excluded) to 3600")
    return value


def start_incidents(session: zenoh.Session, system: System, args: argparse.Namespace) -> Incidents | None:
    """The incident writer ``args`` asks for (None without ``--incidents``); a folder that cannot be made is a
    one-line :class:`SkinetError`."""
    if getattr(args, "incidents", None) is None:
        return None
    try:
        return Incidents(session, bundle(system), Path(args.incidents), args.incident_window,
                         args.incidents_max_files, args.incidents_max_bytes)
    except OSError as exc:
        raise SkinetError(f"--incidents {args.incidents}: cannot make the folder: {exc.strerror}") from None
