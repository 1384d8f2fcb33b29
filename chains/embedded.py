"""Embedded default (docs/semantics.md §7): monitor and predictor on one peer session, with a live view.

``skinet run SYSTEM.toml`` opens one Zenoh ``peer`` session (no router; ZENOH.md:
share one session in a process; loopback only and no multicast scouting unless
asked), starts the monitor, a predictor and the pilot (docs/semantics.md §8; ``--no-pilot``) on it, prints the endpoint it
listens on (a free port is chosen before opening, so that it can be printed)
with the exact commands that reach it, and shows the operator view: redrawn in
place on a terminal, one line per change otherwise.  ``--listen`` lets a bridge
in another process connect; ``--mode client`` runs it behind a router instead.
``skinet router`` runs a Zenoh router from the Python wheel.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import socket
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from services.common.cli import key_style, stop_on_signals
from services.common.endpoints import ZenohSetupError
from services.common.zenoh_config import (
    client_name,
    login,
    open_session,
    session_config,
    session_mode,
    warn_on_stderr,
)
from services.monitor import Monitor, MonitorView, start_monitor
from services.monitor.service import Tap
from services.common.memory import memory_limit
from services.common.options import load_live_system, require_properties, self_ending_options
from skinet.files import program
from skinet.verify.explain import warning_line
from chains.render import seconds, table
from skinet.system.load import load_typemap
from skinet.system.model import System
from skinet.wire import keys
from skinet.wire.convert import missed_line
from skinet.wire.messages import LiveState, StateSpaceReport, UnsafeReport, Verdicts

if TYPE_CHECKING:
    import zenoh

    from services.dashboard.server import Dashboard
    from services.foxglove.feed import PipeFeed

CLEAR = "\x1b[H\x1b[J"  # cursor home, clear to end of screen


RED, YELLOW, PLAIN = "\x1b[1;37;41m", "\x1b[1;30;43m", "\x1b[0m"  # ANSI: white on red, black on yellow, reset


def stale_lines(state: LiveState, colour: bool = False) -> list[str]:
    """The banner of a state the monitor cannot vouch for (docs/semantics.md §7): one line per skillset that is not
    live, with since when and why; none when every skillset is live.  ``colour``: ANSI red for lost,
    yellow for syncing (terminals)."""
    if not state.sync:
        return ["  STATE NOT VOUCHED FOR: this monitor does not say whether it is synced (older than this view)"]
    out = []
    for name, s in state.sync.items():
        if s.state != "live":
            line = f"  STATE {s.state.upper()}: {name} since {_clock(s.since)}: {s.reason}"
            out.append(f"{RED if s.state == 'lost' else YELLOW}{line}{PLAIN}" if colour else line)
    return out


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t))


def render(view: MonitorView | Observed, colour: bool = False) -> list[str]:
    """The operator view: skillsets, properties, unsafe transitions, predictor, counters
    (the last two only from the embedded monitor); a stale state first (``colour``: on a terminal)."""
    st, u = view.state, view.unsafe
    out = [f"SkiNet Live  system {st.system}  step {st.seq}  last event {st.event or '-'}"]
    out += stale_lines(st, colour)
    if st.divergence:
        out.append(f"  MODEL DIVERGENCE: {st.divergence}")
    out += [f"  {missed_line(m)}" for m in st.missed]
    out.append("skillsets")
    width = max(len(n) for n in st.skillsets)
    for name, s in st.skillsets.items():
        res = " ".join(f"{r}={v}" for r, v in s.resources.items())
        sync = st.sync.get(name)
        mark = f"  [{sync.state.upper()} since {_clock(sync.since)}]" if sync and sync.state != "live" else ""
        out.append(f"  {name.ljust(width)}  {res}; running: {', '.join(s.running) or '-'}{mark}")
    out.append("properties")
    for v in view.verdicts.properties:
        line = f"  {v.name}: {'holds' if v.holds else 'VIOLATED'}"
        if not v.holds:
            rec = [f"{r.skillset}:{r.transition}{'' if r.controllable else ' (event)'}"
                   for r in u.recovery if r.property == v.name]
            line += f"; recovery: {', '.join(rec) or 'none'}"
        out.append(line)
    freshness = "STALE (explicit and forced constraints only)" if u.prediction_stale else "fresh"
    out.append(f"unsafe transitions ({len(u.unsafe)}), prediction {freshness}")
    if u.unsafe:
        rows = [[e.skillset, e.transition, e.property, e.constraint,
                 "controllable" if e.controllable else "uncontrollable",
                 "-" if e.steps is None else e.steps, " -> ".join(e.witness)] for e in u.unsafe]
        out.extend("  " + r for r in table(rows, ["skillset", "transition", "property", "constraint",
                                                  "control", "steps", "witness"]).splitlines())
        out.append("why")
        out.extend("  " + warning_line(e) for e in u.unsafe)
    space = view.state_space
    explored = "-" if space is None else (
        f"{seconds(space.time)}, {space.markings} markings, {space.edges} edges, depth {space.depth}, "
        f"{'TRUNCATED' if space.timeout_reached else 'complete'}")
    out.append(f"predictor  last exploration: {explored}")
    if isinstance(view, MonitorView):  # the embedded monitor's own counters
        p, c = view.predictor, view.counters
        out.append(f"  queries sent {p.sent}, answered {p.answered}, timed out {p.timed_out}, unanswered "
                   f"{p.unanswered}, failed {p.failed}, superseded {p.superseded}, retried {p.retried}"
                   f"{', one in flight' if p.in_flight else ''}")
        if p.answers:
            out.append("  answers per instance: " + ", ".join(f"{name} {n}" for name, n in sorted(p.answers.items())))
        out.append(f"events  received {c.received}, applied {c.applied}, malformed {c.malformed}, duplicates "
                   f"{c.duplicates}, out of order {c.out_of_order}, lost {c.lost}, divergences {c.divergences}"
                   + (f", resyncs {c.resyncs}" if c.resyncs else ""))
    return out


@dataclasses.dataclass(frozen=True)
class Observed:
    """The monitor's last messages as an observer received them (``skinet watch``)."""

    state: LiveState
    verdicts: Verdicts
    unsafe: UnsafeReport
    state_space: StateSpaceReport | None


def summary(view: MonitorView | Observed) -> str:
    """One line per change, for logs and pipes."""
    u = view.unsafe
    props = " ".join(f"{v.name}={'ok' if v.holds else 'VIOLATED'}" for v in view.verdicts.properties)
    unsafe = ", ".join(f"{e.skillset}:{e.transition}({e.property} {e.constraint})" for e in u.unsafe) or "none"
    div = f" DIVERGENCE: {view.state.divergence}" if view.state.divergence else ""
    div += "".join(f" | {missed_line(m)}" for m in view.state.missed)
    sync = view.state.sync
    stale = ", ".join(f"{n} {s.state} since {_clock(s.since)}" for n, s in sync.items() if s.state != "live")
    state = f" | STATE STALE: {stale}" if stale else "" if sync else " | state not vouched for"
    return (f"[{view.state.seq}] {view.state.event or 'start'} | {props} | unsafe: {unsafe} | "
            f"prediction {'stale' if u.prediction_stale else 'fresh'}{div}{state}")


def divergence_line(d: Mapping[str, Any], loud: bool = False) -> str:
    """One model divergence or manager restart (a :class:`~skinet.wire.messages.Divergence` as JSON), in the
    operator's words: what (in capitals when ``loud``: a line of its own in a pipe), the monitor step and time,
    the event, why."""
    if d["kind"] == "restart":
        what, words = "manager restart", [d["info"], d["reason"] and f"model divergence: {d['reason']}"]
    elif d["kind"] == "violation":
        what, words = "violation", [d["reason"], d["info"]]
    else:
        what, words = "model divergence", [d["reason"], d["info"]]
    why = "; ".join(w for w in words if w)
    return f"{what.upper() if loud else what} at step {d['seq']} ({_clock(d['stamp'])}): {d['event']}: {why}"


def divergence_lines(entries: Sequence[Mapping[str, Any]], older: int, last: int = 10) -> list[str]:
    """The view's list of model divergences and manager restarts: a count, then the ``last`` ones."""
    total = older + len(entries)
    shown = list(entries[-last:]) if last else []
    out = [f"divergences and manager restarts ({total})"]
    if total > len(shown):
        out.append(f"  ({total - len(shown)} earlier not shown)")
    return out + ["  " + divergence_line(d) for d in shown]


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """``skinet run``: see the module docstring; returns the exit status (the view on ``out``, default the
    standard output of the moment, not of the import)."""
    out = sys.stdout if out is None else out
    from services.predictor.service import start_predictor

    system, _ = load_live_system(args.system)
    require_properties(system, args.system, args.no_properties)
    simulate = getattr(args, "simulate", False)
    duration, failure_rate, seed = self_ending_options(args, "--simulate", simulate)
    mode = session_mode(args, args.connect or [])
    if mode == "client" and args.listen:
        raise ZenohSetupError("--listen: a client listens on nothing (--mode client, or --user with --connect); "
                              "the others connect to its router")
    if mode == "client" and not args.connect and not args.zenoh_config:
        raise ZenohSetupError("--mode client needs the router's endpoint: --connect ENDPOINT")
    config = session_config(mode, args.connect, args.listen, args.zenoh_config, args.multicast_scouting,
                            **login(args))
    listening = fix_free_ports(config) if mode == "peer" else []
    stop = stop_on_signals()
    session = open_session(config, warn_on_stderr("skinet run"))
    monitor: Monitor | None = None
    predictor = None
    dashboard = None
    foxglove = None
    incidents = None
    pilot = None
    robot = None
    try:
        if args.dashboard is not None:  # first: a port in use stops the run before anything starts
            dashboard = start_dashboard(session, system.name, args.dashboard_host, args.dashboard,
                                        client_name(config), system)
            print(f"dashboard on {dashboard.url}", file=sys.stderr, flush=True)
        if getattr(args, "foxglove", None) is not None:  # a port in use stops the run too
            foxglove = spawn_foxglove(args, mode, listening, system.name)
            print(f"foxglove on {foxglove.url}", file=sys.stderr, flush=True)
        limit = memory_limit(args)  # the predictor's workers share it; the pilot's is this whole process's
        predictor = start_predictor(session, f"embedded-{os.getpid()}",  # before the monitor: it asks at once
                                    memory_limit=limit, rate_limit=args.rate_limit)
        from services.monitor.incidents import start_incidents

        incidents = start_incidents(session, system, args)
        monitor = start_monitor(session, system, budget=args.budget, check_policy=args.check_policy,
                                client=client_name(config), check_rate_limit=args.check_rate_limit,
                                lost_after=args.lost_after,
                                tap=taps(None if incidents is None else incidents.record,
                                         None if foxglove is None else foxglove.feed.record))
        if not args.no_pilot:
            from services.pilot import start_pilot

            pilot = start_pilot(session, system, instance=f"embedded-{os.getpid()}", client=client_name(config),
                                typemap=load_typemap(args.system), style=key_style(args),
                                outcome_timeout=args.outcome_timeout, memory_limit=limit)
        if simulate:
            from chains.simulated import start_simulated_robot

            robot = start_simulated_robot(session, system, load_typemap(args.system), instance=f"embedded-{os.getpid()}",
                                          style=key_style(args), duration=duration, failure_rate=failure_rate,
                                          seed=seed)
        print("\n".join(connect_lines(args, system, mode, listening, pilot=pilot is not None,
                                     simulated=(duration, failure_rate, seed) if simulate else None)),
              file=sys.stderr, flush=True)
        if args.once:
            deadline = time.monotonic() + args.budget + 2.0  # the first prediction, if any comes
            view = monitor.snapshot()
            while view.unsafe.prediction_stale and time.monotonic() < deadline:
                monitor.wait_change(view.version, 0.1)
                view = monitor.snapshot()
            print("\n".join(render(view)), file=out, flush=True)
            return 0
        _follow(monitor, stop, args.duration, out)
        return 0
    finally:
        if dashboard is not None:
            dashboard.close()
            dashboard.observer.close()
        if foxglove is not None:
            foxglove.close()
        if pilot is not None:
            pilot.close()
        if monitor is not None:
            monitor.close()
        if incidents is not None:  # after the monitor: a pending bundle gets its last messages
            incidents.close()
        if robot is not None:  # after the monitor, which would report the robot's bridge gone
            robot.close()
        session.close()
        if predictor is not None:
            predictor.close()


def fix_free_ports(config: zenoh.Config) -> list[str]:
    """The ``listen`` endpoints, ``tcp/HOST:0`` given a free port now (so that it can be printed)."""
    given = json.loads(config.get_json("listen/endpoints") or "[]")
    if not isinstance(given, list):  # per mode, in a configuration file: left as it is
        return []
    endpoints = []
    for endpoint in map(str, given):
        m = re.fullmatch(r"tcp/(\[?[^\]]*\]?|[^:]+):0", endpoint)
        if m:
            host = m.group(1).strip("[]")
            try:
                with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as probe:
                    probe.bind((host, 0))
                    endpoint = f"tcp/{m.group(1)}:{probe.getsockname()[1]}"
            except OSError:
                pass  # Zenoh says why it cannot listen there
        endpoints.append(endpoint)
    config.insert_json5("listen/endpoints", json.dumps(endpoints))
    return endpoints


def connect_lines(args: argparse.Namespace, system: System, mode: str, listening: list[str],
                  prog: str = "skinet run", bridge: bool = True, pilot: bool = False,
                  simulated: tuple[float, float, int] | None = None) -> list[str]:
    """What ``skinet run`` (or ``prog``) prints at start: where it listens, and the exact commands that reach it
    (``bridge``: the bridge's too, for the system file ``args.system``, unless ``simulated`` (skill duration,
    failure rate, seed) says that the run simulates the robot itself; ``pilot``: the pilot's goal key)."""
    if mode == "peer":
        endpoint = next((e for e in listening if e.startswith("tcp/")), listening[0] if listening else "")
        endpoint = re.sub(r"^tcp/0\.0\.0\.0:", "tcp/127.0.0.1:", re.sub(r"^tcp/\[::\]:", "tcp/[::1]:", endpoint))
        head = f"{prog}: system {system.name}, listening on {', '.join(listening)}; connect with:"
    else:
        endpoint = (args.connect or ["(its --zenoh-config router)"])[0]
        head = f"{prog}: system {system.name}, a client of the router at {endpoint}; connect with:"
    folder = Path(args.password_file).parent if args.password_file else Path("~/.config/skinet/secrets")

    def flags(user: str) -> str:  # a router's users log in; a peer of skinet run takes no login
        login = mode == "client" and args.user
        return f"-e {endpoint}" + (f" --user {user} --password-file {folder / f'{user}.password'}" if login else "")

    first = system.components[0]
    command = f"{first.name}:{first.skillset.skills[0].name}.start" if first.skillset.skills else "SKILLSET:TRANSITION"
    skinet = program.skinet()
    lines = [head, f"  {skinet} watch {system.name} {flags('observer')}",
             f"  {skinet} dashboard {system.name} {flags('observer')}",
             f"  {skinet} check {system.name} {command} {flags('observer')}"]
    if simulated is not None:
        duration, rate, seed = simulated
        lines.append(f"  the robot: simulated here, with its bridge; each skill ends by itself {duration:g} s after it "
                     f"starts (failure rate {rate:g}, seed {seed})")
    elif bridge:
        ros = (" --rmw-zenoh" + (f" --domain {args.domain}" if args.domain else "") + (
            " --ros-distro humble" if args.ros_distro == "humble" else "") if args.rmw_zenoh else "") + (
            f" --namespace {args.namespace}" if args.namespace else "")  # the robot's keys, as the pilot's
        lines.append(f"  {program.python()} -m services.bridge_ros2 {args.system}{ros} {flags('bridge')}   (the robot's side)")
    if pilot:
        lines.append(f"  pilot: goals on {keys.pilot_goal(system.name, '<client>')} (<client>: your login, "
                     f"'{keys.LOCAL_CLIENT}' without one), status on {keys.pilot_status(system.name)}")
        runnable = [f"run {c.name}:{k.name}" for c in system.components for k in c.skillset.skills
                    if k.successes and not k.inputs]
        goal = f"  {skinet} goal {system.name} \"{runnable[0] if runnable else 'reach FORMULA'}\""
        lines.append(f"{goal} --drive {flags('operator')}   (the pilot drives the simulated robot)" if simulated
                     else f"{goal} {flags('operator')}   (guided; --drive: the pilot sends the commands)")
    return lines


def start_dashboard(session: zenoh.Session, name: str, host: str, port: int, client: str,
                    model: System | None = None) -> Dashboard:
    """The web dashboard of system ``name`` on the shared session (``model`` gives the timeline's
    lanes before the model bundle is fetched); raises :class:`PortError` (port in use)."""
    from services.dashboard.observer import Observer
    from services.dashboard.server import Dashboard

    observer = Observer(session, name, model, client=client)
    dashboard = Dashboard(observer, host, port)
    try:
        dashboard.start()
    except Exception:
        observer.close()
        raise
    return dashboard


FOXGLOVE_START = 30.0  # seconds for the Foxglove view's process to say where it serves


def taps(*fns: Tap | None) -> Tap | None:
    """The monitor's tap handing each message to every one of ``fns`` given, in order (None: none given)."""
    given = tuple(f for f in fns if f is not None)
    if len(given) < 2:
        return given[0] if given else None

    def each(key: str, payload: bytes, t: float = 0.0) -> None:
        for fn in given:
            fn(key, payload, t)
    return each


@dataclasses.dataclass
class FoxgloveProcess:
    """``python -m services.foxglove`` beside ``skinet run``: a process of its own, so that its Python work never
    holds the monitor's interpreter (benchmarks/bench_latency.py: in the same process, p99 several times the
    monitor's), fed the monitor's results through a pipe (``feed``, the monitor's tap) rather than Zenoh (a
    remote subscriber of the monitor's keys doubles its p99; :mod:`services.foxglove.feed`, docs/foxglove.md)."""

    proc: Any
    url: str
    feed: PipeFeed

    def close(self) -> None:
        self.feed.close()  # the view ends with its pipe; terminated too, in case it waits for something else
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except Exception:
            self.proc.kill()


def spawn_foxglove(args: argparse.Namespace, mode: str, listening: list[str], system: str) -> FoxgloveProcess:
    """Start the Foxglove view of ``skinet run`` (a peer of its listen endpoint, or a client of the same router
    with the same login, for the model, the pilot and liveliness; the monitor's results of ``system`` through a
    pipe); raises a one-line :class:`SkinetError` with the view's own error (port in use)."""
    import subprocess

    from services.foxglove.feed import PipeFeed
    from skinet.errors import SkinetError

    zenoh_args = ["--no-multicast-scouting"]
    if mode == "peer":
        endpoint = next((e for e in listening if e.startswith("tcp/")), None)
        if endpoint is None:
            raise SkinetError("--foxglove needs a tcp/ listen endpoint (--listen tcp/127.0.0.1:0)")
        endpoint = re.sub(r"^tcp/0\.0\.0\.0:", "tcp/127.0.0.1:", re.sub(r"^tcp/\[::\]:", "tcp/[::1]:", endpoint))
        zenoh_args += ["--mode", "peer", "-e", endpoint]
    else:
        zenoh_args += ["--mode", "client", *(x for e in args.connect or [] for x in ("-e", e))]
        for option in ("zenoh_config", "user", "password_file"):
            if getattr(args, option, None):
                zenoh_args += [f"--{option.replace('_', '-')}", str(getattr(args, option))]
    read, write = os.pipe()
    try:
        proc = subprocess.Popen([sys.executable, "-m", "services.foxglove", str(args.system), "--host",
                                 args.foxglove_host, "--port", str(args.foxglove), "--wait", "30", "--feed", str(read),
                                 *zenoh_args],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                pass_fds=(read,), env={**os.environ, **({"SKINET_ZENOH_PASSWORD": args.password}
                                                                       if getattr(args, "password", None) else {})})
    except BaseException:
        os.close(write)
        raise
    finally:
        os.close(read)
    feed = PipeFeed(system, write)
    lines: list[str] = []
    deadline = time.monotonic() + FOXGLOVE_START
    while time.monotonic() < deadline:
        line = proc.stderr.readline() if proc.stderr else ""
        if not line:
            break
        lines.append(line.strip())
        m = re.search(r" on (ws://\S+)", line)
        if line.startswith("skinet foxglove:") and m:
            threading.Thread(target=_drain, args=(proc.stderr,), daemon=True).start()
            return FoxgloveProcess(proc, m.group(1), feed)
    feed.close()
    proc.kill()
    proc.wait()
    error = next((x for x in reversed(lines) if "error" in x), lines[-1] if lines else "it stopped at once")
    raise SkinetError(f"--foxglove: {error.split('error: ', 1)[-1]}")


def _drain(stream: TextIO) -> None:
    """Pass the view's later lines (warnings) on to this process's standard error."""
    for line in stream:
        if "foxglove.websocket.server INFO" not in line:
            sys.stderr.write(line)


def _follow(monitor: Monitor, stop: threading.Event, duration: float | None, out: TextIO) -> None:
    """Redraw (terminal) or log (pipe) the view whenever it changes, until stopped; the divergences and
    manager restarts are listed below the view, or a line each in a pipe."""
    tty = out.isatty()
    end = None if duration is None else time.monotonic() + duration
    shown: tuple | None = None
    listed, noted = 0, monitor.divergences()
    while not stop.is_set() and (end is None or time.monotonic() < end):
        view = monitor.snapshot()
        stats = dataclasses.astuple(view.predictor)
        if shown is None or view.version != shown[0] or (tty and stats != shown[1]):
            if monitor.divergences_published != noted.older + len(noted.entries):
                noted = monitor.divergences()
            entries = [d.model_dump(mode="json") for d in noted.entries]
            if tty:
                lines = render(view, colour=True) + divergence_lines(entries, noted.older)
                out.write(CLEAR + "\n".join(lines) + "\n")
            else:
                out.write(summary(view) + "\n")
                out.writelines(divergence_line(d, loud=True) + "\n" for d in entries if d["n"] >= listed)
                listed = noted.older + len(noted.entries)
            out.flush()
            shown = (view.version, stats)
        monitor.wait_change(view.version, 0.25)


def router(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """``skinet router``: a Zenoh router (mode "router" of the Python wheel) until interrupted.

    Secure by default (issue 14): loopback only unless ``--listen`` says otherwise,
    and user/password authentication: the ``dictionary_file`` of the configuration,
    or ``users.txt`` in the secrets folder; missing users get random passwords at
    first start (:func:`~services.common.security.ensure_users`).  A ``tls/``
    endpoint without certificates in the configuration gets a CA and certificates
    (the router's, and one per user for clients) made in ``<secrets>/tls``, with
    mutual TLS; ``$SKINET_TLS_HOSTNAMES`` lists the names clients reach it by.
    A folder with ``tls/ca.pem`` but no CA key holds the router's own certificate,
    handed out by the compose job ``secrets`` (:mod:`services.secrets`): the router
    then makes no certificate, and a missing one is a one-line error.

    Fleet (issue 15): a robot's router that joined a hub (``skinet fleet join``)
    also trusts the fleet CA and takes the fleet's password for the user ``hub``;
    with ``--robots`` (``$SKINET_FLEET_ROBOTS``) the router is the hub, linked to
    each robot's router over mutual TLS as ``hub`` (:func:`~services.common.security.hub_endpoints`).
    """
    from services.common.security import (
        USERS, ensure_fleet, ensure_tls, ensure_users, hub_endpoints, robot_fleet, tls_listen_config,
    )

    stop = stop_on_signals()
    config = session_config("router", args.connect, args.listen, args.zenoh_config, args.multicast_scouting,
                            **login(args))
    folder = Path(args.secrets or Path.home() / ".config" / "skinet" / "secrets")
    table = json.loads(config.get_json("transport/auth/usrpwd/dictionary_file") or "null")
    if table and not args.no_auth:
        folder = Path(table).parent
    if getattr(args, "handed", None):  # compose: the job's hand-out, read-only here, copied into the router's own
        from services.secrets.handout import take_handed

        take_handed(Path(args.handed), folder)
    certificates = folder / "tls"
    # The router's own files handed out by the compose job `secrets`: no CA key, no client's password file.
    handed_out = (certificates / "ca.pem").exists() and not (certificates / "ca.key").exists()
    notes = []
    if not args.no_auth:
        ensure_users(folder, fixed=robot_fleet(folder)[1], password_files=not handed_out)
        config.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(folder / "users.txt")))
        notes.append(f"users and passwords in {folder}")
    endpoints = json.loads(config.get_json("listen/endpoints"))
    if any(str(e).startswith("tls/") for e in endpoints) and \
            json.loads(config.get_json("transport/link/tls/listen_certificate") or "null") is None:
        hostnames = [h.strip() for h in os.environ.get("SKINET_TLS_HOSTNAMES", "").split(",") if h.strip()]
        ensure_tls(certificates, ["router"] if handed_out else ["router", *USERS], hostnames)
        tls = tls_listen_config(folder / "tls", "router")
        trusted, _ = robot_fleet(folder)
        if trusted is not None:  # the robot joined a fleet: the hub's certificate is of the fleet CA
            tls["root_ca_certificate"] = str(trusted)
            notes.append("member of a fleet (trusts its hub)")
        config.insert_json5("transport/link/tls", json.dumps(tls))
        notes.append(f"TLS certificates in {folder / 'tls'}")
    robots = [r.strip() for r in (args.robots or "").split(",") if r.strip()]
    if robots:
        links, left_out = hub_endpoints(folder, robots)
        for note in left_out:
            print(f"skinet router: {note}", file=sys.stderr, flush=True)
        known = json.loads(config.get_json("connect/endpoints") or "[]")
        config.insert_json5("connect/endpoints", json.dumps([*known, *links]))
        config.insert_json5("transport/auth/usrpwd/user", json.dumps("hub"))
        config.insert_json5("transport/auth/usrpwd/password", json.dumps(ensure_fleet(folder)))
        notes.append(f"hub of {len(links)} of {len(robots)} robots")
    session = open_session(config, warn_on_stderr("skinet router"))
    try:
        print(f"zenoh router {session.zid()} listening on {', '.join(endpoints)}"
              + "".join(f"; {n}" for n in notes), file=out, flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        session.close()
    return 0

