"""``skinet record``: write what is published under ``skinet/<system>/**`` to a monitor log;
``skinet rosbag``: write what the bridge reads to a rosbag2, without ROS
(:mod:`services.bridge_ros2.record`).

A thin Zenoh shell over :mod:`skinet.wire.log` and :mod:`skinet.wire.mcap_log`:
every sample is decoded with the codec (the key says which message to expect)
and written with its receive time, as one flushed JSON line or as an MCAP
message (JSON with JSON schemas, for Foxglove); undecodable payloads are
counted and skipped.  The model bundle is asked for once, so that ``skinet timeline`` knows
every skill and resource of the system.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
import uuid
from typing import TYPE_CHECKING, BinaryIO, TextIO

import zenoh
from pydantic import BaseModel

from services.common.zenoh_config import (
    add_zenoh_args, config_from_args, connect_problems, open_session, shown_endpoint, warn_on_stderr,
)
from services.bridge_ros2.record import STORAGES, BagRecorder, recorded_topics
from services.common.cli import add_ros_key_args, key_style
from skinet.files import program
from skinet.system.load import load_bindings, load_typemap
from services.common.options import count, key_name, load_live_system, print_warnings, seconds
from skinet.errors import SkinetError, SourceError
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode
from skinet.wire.log import log_line
from skinet.wire.mcap_log import McapLogWriter
from skinet.wire.messages import (
    MESSAGES, CanonicalEvent, Divergences, LiveState, ModelBundle, PilotStatus, StateSpaceReport, UnsafeReport,
    Verdicts,
)

if TYPE_CHECKING:
    from services.foxglove.bundle import BundleSink

BY_KEY: dict[str, type[BaseModel]] = {
    "events": CanonicalEvent, "state": LiveState, "verdicts": Verdicts, "unsafe": UnsafeReport,
    "state_space": StateSpaceReport, "model": ModelBundle, "divergences": Divergences, "pilot": PilotStatus,
}
SHOW_SKIPPED = 5  # undecodable payloads reported on standard error, then only counted
MODEL_RETRY = 2.0  # seconds between model queries while none answered


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("record", help="record the monitor's messages of a system into a JSON Lines log")
    c.add_argument("system", metavar="SYSTEM_NAME", type=key_name("system name"),
                   help="system name, as in skinet/<system>/... keys")
    out = c.add_mutually_exclusive_group(required=True)
    out.add_argument("-o", "--output", metavar="LOG.jsonl|LOG.mcap", help="log file to write (overwritten)")
    out.add_argument("--bundle", metavar="FILE.mcap",
                     help="write an incident bundle instead (overwritten): MCAP with the model as attachments and "
                          "their digests, the events, verdicts, unsafe reports, divergences and pilot statuses, and "
                          "the Foxglove channels of skinet foxglove; skinet replay FILE --verify re-runs it")
    c.add_argument("--format", choices=["jsonl", "mcap"],
                   help="JSON Lines, or MCAP with JSON schemas (Foxglove, other robotics tools); default: from "
                        "the extension of --output (.mcap: mcap, else jsonl). MCAP is finished on Ctrl-C, "
                        "SIGTERM, --duration or --count")
    c.add_argument("--duration", type=seconds(), help="stop after this many seconds (default: until Ctrl-C)")
    c.add_argument("--count", type=count(), help="stop after writing this many messages")
    c.add_argument("--no-model", action="store_true", help="do not query the monitor's model bundle")
    add_zenoh_args(c)
    c.set_defaults(func=cmd_record)
    b = sub.add_parser(
        "rosbag", help="record the robot's ROS 2 topics the bridge reads into a rosbag2 (no ROS needed)",
        description="Record, through Zenoh, every topic the bridge derives the system's events from (the skillset "
                    "managers' status, event and skill-response topics; the bindings' action statuses, lifecycle "
                    "transition events and bound topics) into a rosbag2 folder, MCAP storage by default. "
                    "skinet conform replays it, and ros2 bag info/play read it. Stops on Ctrl-C, SIGTERM or "
                    "--duration; exit 1 when nothing was recorded.")
    b.add_argument("system", metavar="SYSTEM.toml", help="system file (bound skillsets name their binding file)")
    b.add_argument("-o", "--output", required=True, metavar="BAG", help="rosbag2 folder to create (must not exist)")
    b.add_argument("--storage", choices=sorted(STORAGES), default="mcap", help="storage plugin (default: mcap)")
    b.add_argument("--duration", type=seconds(), help="stop after this many seconds (default: until Ctrl-C)")
    add_ros_key_args(b)
    add_zenoh_args(b)
    b.set_defaults(func=cmd_rosbag)


def message_type(system: str, key: str) -> type[BaseModel] | None:
    """The message expected on ``key`` (None: unknown key, try every type)."""
    parts = key.split("/")
    if len(parts) >= 3 and parts[0] == keys.ROOT and parts[1] == system:
        return BY_KEY.get(parts[2])
    return None


def decode_any(system: str, key: str, payload: bytes) -> BaseModel:
    """Decode ``payload`` as the message its key implies; raises :class:`DecodeError`."""
    kind = message_type(system, key)
    if kind is not None:
        return decode(payload, kind)
    for candidate in MESSAGES.values():
        try:
            return decode(payload, candidate)
        except DecodeError:
            continue
    raise DecodeError("not any known message")


class JsonlSink:
    """JSON Lines, one flushed line per message."""

    def __init__(self, out: TextIO):
        self.out = out

    def write(self, key: str, message: BaseModel, t: float) -> None:
        self.out.write(log_line(key, message, t) + "\n")
        self.out.flush()

    def close(self) -> None:
        self.out.close()


class McapSink:
    """MCAP with JSON schemas (:mod:`skinet.wire.mcap_log`)."""

    def __init__(self, out: BinaryIO):
        self.out, self.writer = out, McapLogWriter(out)

    def write(self, key: str, message: BaseModel, t: float) -> None:
        self.writer.write(key, message, t)

    def close(self) -> None:
        self.writer.finish()
        self.out.close()


class Recorder:
    """Writes decoded samples to ``sink`` (thread-safe); ``done`` is set after ``count`` messages."""

    def __init__(self, sink: JsonlSink | McapSink | BundleSink, system: str, count: int | None = None):
        self.sink, self.system, self.count = sink, system, count
        self.written = 0
        self.skipped = 0
        self.has_model = False
        self.want_model = threading.Event()  # a monitor published: ask for its model now, not at the next retry
        self.done = threading.Event()
        self._lock = threading.Lock()

    def on_sample(self, sample: zenoh.Sample) -> None:
        if sample.kind != zenoh.SampleKind.PUT:
            return
        self.add(str(sample.key_expr), sample.payload.to_bytes(), time.time())

    def on_reply(self, reply: zenoh.Reply) -> None:
        if reply.ok is not None:
            self.add(str(reply.ok.key_expr), reply.ok.payload.to_bytes(), time.time())

    def add(self, key: str, payload: bytes, t: float) -> None:
        try:
            message = decode_any(self.system, key, payload)
        except DecodeError as exc:
            with self._lock:
                self.skipped += 1
                if self.skipped <= SHOW_SKIPPED:
                    print(f"skinet record: skipped undecodable payload on {key}: {exc}", file=sys.stderr)
            return
        with self._lock:
            if self.done.is_set():
                return
            if isinstance(message, LiveState) and not self.has_model:
                self.want_model.set()
            if isinstance(message, ModelBundle):
                if self.has_model:
                    return
                self.has_model = True
            self.sink.write(key, message, t)
            self.written += 1
            if self.count is not None and self.written >= self.count:
                self.done.set()

    def close(self) -> None:
        """Stop writing (later samples are dropped) and close the log."""
        with self._lock:
            self.done.set()
            self.sink.close()


def cmd_record(args: argparse.Namespace) -> int:
    system = args.system
    config = config_from_args(args, command=True)
    said: list[str] = []  # the warnings about endpoints: the end does not say them again
    shout = warn_on_stderr("skinet record")

    def warn(message: str) -> None:
        said.append(message)
        shout(message)

    session = open_session(config, warn)
    if args.bundle is not None:
        args.output = args.bundle
    mcap = (args.format or ("mcap" if args.output.endswith(".mcap") else "jsonl")) == "mcap"
    try:
        if args.bundle is not None:
            from services.foxglove.bundle import BundleSink

            sink: JsonlSink | McapSink | BundleSink = BundleSink(open(args.output, "wb"), system)
        else:
            sink = McapSink(open(args.output, "wb")) if mcap else JsonlSink(open(args.output, "w", encoding="utf-8"))
    except OSError as exc:
        session.close()
        raise SourceError.at(args.output, None, f"cannot write file: {exc.strerror}") from None
    recorder = Recorder(sink, system, args.count)
    stop = recorder.done
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        _sub = session.declare_subscriber(f"{keys.ROOT}/{system}/**", recorder.on_sample)  # noqa: F841 (kept alive)
        _token = session.liveliness().declare_token(keys.alive(system, "recorder", uuid.uuid4().hex[:8]))  # noqa: F841
        print(f"skinet record: recording {keys.ROOT}/{system}/** to {args.output}", file=sys.stderr)
        deadline = None if args.duration is None else time.monotonic() + args.duration
        asked = -MODEL_RETRY
        while not stop.is_set():
            now = time.monotonic()
            if deadline is not None and now >= deadline:
                break
            if not args.no_model and not recorder.has_model and (now - asked >= MODEL_RETRY
                                                                   or recorder.want_model.is_set()):
                asked = now
                recorder.want_model.clear()
                session.get(keys.model(system), handler=recorder.on_reply, timeout=MODEL_RETRY)
            stop.wait(0.1 if deadline is None else max(0.0, min(0.1, deadline - now)))
    except KeyboardInterrupt:
        pass
    finally:
        if args.bundle is not None and not recorder.has_model and not args.no_model:
            try:  # a last, blocking ask: a short run may end before the retry (the monitor may still answer)
                for reply in session.get(keys.model(system), timeout=MODEL_RETRY):
                    if reply.ok is not None and not recorder.has_model:  # after the stop: past Recorder.add
                        recorder.sink.write(str(reply.ok.key_expr), decode(reply.ok.payload.to_bytes(), ModelBundle),
                                            time.time())
                        recorder.has_model = True
            except Exception:  # the session closing under a signal: the bundle says it has no model
                pass
        try:
            recorder.close()  # a bundle without a model: a one-line error
        finally:
            why = _nothing_recorded(session, config, system, said) if recorder.written == 0 else None
            session.close()
    if why is not None:  # an empty log is never a success
        raise SkinetError(f"nothing recorded in {args.output}: {why}")
    print(f"skinet record: {recorder.written} messages written to {args.output}"
          f" ({recorder.skipped} undecodable skipped)", file=sys.stderr)
    return 0



def cmd_rosbag(args: argparse.Namespace) -> int:
    system, warnings = load_live_system(args.system)
    bindings, more = load_bindings(system)
    print_warnings([*warnings, *more])
    topics = recorded_topics(system, load_typemap(args.system), bindings, key_style(args))
    if os.path.lexists(args.output):
        raise SourceError.at(args.output, None, "already exists: a rosbag2 is written to a new folder")
    if not os.path.isdir(os.path.dirname(os.path.abspath(args.output))):
        raise SourceError.at(args.output, None, "cannot write: No such file or directory")
    session = open_session(config_from_args(args), warn_on_stderr("skinet rosbag"))
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        try:
            recorder = BagRecorder(session, args.output, topics, storage=args.storage)
        except OSError as exc:
            raise SourceError.at(args.output, None, f"cannot write: {exc.strerror or exc}") from None
        print(f"skinet rosbag: recording {len(topics)} topics of {system.name} to {args.output} "
              f"({args.storage})", file=sys.stderr)
        try:
            stop.wait(args.duration)
        except KeyboardInterrupt:
            pass
        finally:
            recorder.close()
    finally:
        session.close()
    for name, n in recorder.counts.items():
        print(f"  {n:6d}  {name}", file=sys.stderr)
    if recorder.messages == 0:  # an empty bag is never a success
        raise SkinetError(f"nothing recorded in {args.output}: no message on the {len(topics)} topics (is the robot "
                          "or its gateway connected to this Zenoh network? check -e/--connect and --namespace)")
    print(f"skinet rosbag: {recorder.messages} messages written to {args.output}; replay it with "
          f"{program.skinet()} conform {args.system} {args.output}", file=sys.stderr)
    return 0


def _nothing_recorded(session: zenoh.Session, config: zenoh.Config, system: str, said: list[str]) -> str:
    """Why no message came: an endpoint not reached (named only when one of the warnings ``said`` at the
    start gave its reason), or no monitor of ``system`` (naming those seen)."""
    from services.common.session import unconnected
    from services.dashboard.observer import monitored_systems

    missing = [shown_endpoint(e) for e in unconnected(session, config)]
    if missing and all(any(f"cannot connect to {e}: " in m for m in said) for e in missing):
        return f"no link to {', '.join(missing)} came up (the warning above says why)"
    if missing:
        return "; ".join(connect_problems(session, config))
    others = monitored_systems(session)
    return (f"no monitor of system '{system}' published anything "
            f"({'systems with a monitor: ' + ', '.join(others) if others else 'no monitor is reachable'})")
