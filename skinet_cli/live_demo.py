"""``skinet demo --live``: one run played in real time through the whole chain, for the views to follow.

The run goes through simulated managers, CDR, the bridge, the monitor and a predictor
on one Zenoh session that listens (a peer on ``tcp/127.0.0.1`` and a free port, or
``--listen``, or a client of a router with ``--connect``), at the scenario's times
divided by ``--speed``.  It prints where it listens and the exact ``skinet watch``,
``skinet dashboard`` and ``skinet check`` lines that reach it, serves the dashboard
itself with ``--dashboard PORT``, prints each step as the monitor showed it, then keeps
every service running until Ctrl-C (or ``--linger`` seconds) so that the views stay.
As everywhere: an explicit ``--connect`` endpoint that does not answer stops it with
the reason; a dashboard port in use stops it before the run starts.  Zenoh and the web
server are imported when it runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from services.common.zenoh_config import add_zenoh_args
from skinet.mission.scenario import Scenario, StepRecord
from skinet.system.model import System
from services.common.options import count, number, seconds

CONNECT_WAIT = 2.0  # seconds for an explicit --connect endpoint to answer before the demo gives up
# Options that only --live takes, whose default is None (the login's and --mode's come from the environment).
LIVE_OPTIONS = ("speed", "linger", "dashboard", "connect", "listen")


def add_live_args(c: argparse.ArgumentParser) -> None:
    """``--live`` and the options that go with it."""
    g = c.add_argument_group("live (with --live)")
    g.add_argument("--live", action="store_true",
                   help="play one run (default: the paper's unassisted run) in real time through the whole chain, "
                        "served to other processes: prints the skinet watch, dashboard and check lines that reach "
                        "it, then keeps running until Ctrl-C")
    g.add_argument("--speed", type=number(0), metavar="X",
                   help="time scale of --live: a step at t seconds is played at t/X; 0: as fast as the chain "
                        "settles (default: 1, real time)")
    g.add_argument("--dashboard", type=count(0, 65535), metavar="PORT",
                   help="serve the live web dashboard of --live on this port (0: a free one)")
    g.add_argument("--dashboard-host", default="127.0.0.1", help="address of --dashboard (default: 127.0.0.1)")
    g.add_argument("--linger", type=seconds(zero=True), metavar="S",
                   help="after the run, keep the chain and the dashboard running this many seconds (default: "
                        "until Ctrl-C or SIGTERM)")
    add_zenoh_args(c)


def live_options_misused(args: argparse.Namespace) -> str | None:
    """The first option given that only ``--live`` takes, when ``--live`` is not given."""
    if args.live:
        return None
    given = [name for name in LIVE_OPTIONS if getattr(args, name, None) not in (None, [])]
    return f"--{given[0].replace('_', '-')} needs --live" if given else None


@contextmanager
def live_session(args: argparse.Namespace, system: System, header: str) -> Iterator[tuple[Any, Callable[[], None]]]:
    """The session a live run plays on, as the module docstring says: yields it once the dashboard is up and the
    connect lines and ``header`` are printed, with ``linger()``, which keeps the views running until Ctrl-C or
    ``--linger``.  Raises one-line :class:`~skinet.errors.SkinetError` (unreachable endpoint, refused login,
    port in use)."""
    from services.common.zenoh_config import (
        check_connected, client_name, config_from_args, open_session, said_at_the_end, wait_connected,
    )
    from chains.embedded import connect_lines, fix_free_ports, start_dashboard
    from services.common.cli import stop_on_signals

    config = config_from_args(args)
    mode = json.loads(config.get_json("mode"))
    listening = fix_free_ports(config) if mode == "peer" else []
    session = open_session(config, said_at_the_end)
    dashboard = None
    try:
        if not wait_connected(session, config, CONNECT_WAIT):  # a run nobody asked for where it was asked
            check_connected(session, config)
        if args.dashboard is not None:  # first: a port in use stops the demo before the run starts
            dashboard = start_dashboard(session, system.name, args.dashboard_host, args.dashboard,
                                        client_name(config), system)
            print(f"dashboard on {dashboard.url}", file=sys.stderr, flush=True)
        print("\n".join(connect_lines(args, system, mode, listening, prog="skinet demo", bridge=False)),
              file=sys.stderr, flush=True)
        print(header, flush=True)

        def linger() -> None:
            stop = stop_on_signals()  # during the run Ctrl-C interrupts it (KeyboardInterrupt), SIGTERM ends it
            print("skinet demo: the run is over; the chain keeps running for the views "
                  + ("(Ctrl-C stops it)" if args.linger is None else f"for {args.linger:g} s"),
                  file=sys.stderr, flush=True)
            stop.wait(args.linger)

        yield session, linger
    finally:
        if dashboard is not None:
            dashboard.close()
            dashboard.observer.close()
        session.close()


def play_live(args: argparse.Namespace, path: Path, scenario: Scenario, system: System, header: str,
              on_record: Callable[[StepRecord], None], after: Callable[[list[StepRecord]], None],
              then: Callable[[Any], None] | None = None) -> list[StepRecord]:
    """Play ``scenario`` on a :func:`live_session`: ``on_record`` after each step, ``then`` after the last step (a
    bound system's chain: the pilot's goals, :func:`chains.chain.run_bound_chain`), ``after`` once the run is
    over (then the chain keeps running until Ctrl-C or ``--linger``)."""
    from chains.chain import run_any_chain

    with live_session(args, system, header) as (session, linger):
        def over(records: list[StepRecord]) -> None:
            after(records)
            linger()

        speed = 1.0 if args.speed is None else args.speed
        return run_any_chain(system, path.parent / scenario.system, scenario, then=then, session=session, speed=speed,
                             on_record=on_record, after=over)
