"""``skinet watch`` in a pipe (issue 27, item 8): one line per monitor step, as its help says.

The monitor publishes a step more than once (its prediction pending, then fresh), and
services come and go; a pipe used to get a line for each of those.  Real processes: a
loopback router, the monitor and a predictor on a client session, ``skinet watch`` as a
child process writing into a pipe.
"""

from __future__ import annotations

import io
import re
import subprocess
import sys
import threading
import time

import zenoh

from chains.chain import embedded_services
from chains.watch import StepLines
from services.monitor import start_monitor
from skinet.system.load import load_system
from skinet.wire import keys
from tests.services.conftest import REPO, LivelinessWatch, client_args, open_client
from tests.services.test_monitor import Events, wait_until

SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
STEPS = [("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
         ("spot", "stand_up.success.standing")]


def test_watch_in_a_pipe_prints_one_line_per_step(router: str, client: zenoh.Session, client_factory) -> None:
    system = load_system(SYSTEM_FILE)[0]
    with embedded_services(client_factory(), system, True, budget=1.0) as (_, monitor, _):
        events = Events(client)  # the bridge's side: the monitor is synced (a monitor still syncing is a line too)
        alive = LivelinessWatch(client, keys.alive("spot_arm", "monitor", "*"))
        proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "watch", "spot_arm", "--duration", "60",
                                 *client_args(router)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        printed: list[str] = []
        reader = threading.Thread(target=lambda: printed.extend(iter(proc.stdout.readline, "")),  # type: ignore[union-attr]
                                  daemon=True)
        reader.start()
        try:
            alive.wait(lambda names: bool(names))
            wait_until(lambda: monitor.snapshot().state_space is not None, 20, "the first prediction")
            # Step 0's line, written once the watcher has step 0 with its fresh prediction: sending step 1 before
            # (a fixed pause, once) lost it when the watcher started late on a loaded machine.
            wait_until(lambda: any(line.startswith("[0] ") for line in printed), 30, "the line of step 0")
            for n, (skillset, transition) in enumerate(STEPS, 1):
                events.send(skillset, transition)
                # Its line comes once the watcher has the step's fresh prediction (the next step would write it
                # as it is): the next event waits for it, however loaded the machine.
                wait_until(lambda: any(line.startswith(f"[{n}] ") for line in printed), 20, f"the line of step {n}")
        finally:
            proc.terminate()
            proc.wait(20)
            reader.join(10)  # the pipe's last lines
            err = proc.stderr.read()  # type: ignore[union-attr]
            alive.close()
    out = "".join(printed)
    lines = out.splitlines()
    assert [int(re.match(r"\[(\d+)\]", line).group(1)) for line in lines] == [0, 1, 2, 3, 4], out + err
    assert all(line.endswith("prediction fresh") for line in lines), out
    assert [line.split(" | ")[0] for line in lines[1:]] == [f"[{n}] {s}:{t}#{n}" for n, (s, t) in enumerate(STEPS, 1)]


DIVERGENCE = r"MODEL DIVERGENCE at step {step} \(\d\d:\d\d:\d\d\): spot:init_power.success.powered_on#{seq}: " \
             r"'init_power.success.powered_on' is not enabled in the live marking"


def test_watch_lists_divergences_and_a_late_joiner_gets_the_list_so_far(router: str, client: zenoh.Session) -> None:
    """Issue 27 item 4: a divergence is listed for the rest of the run, not only on its step's line; a watch
    started after it (in a pipe, or --once) gets it from the monitor."""
    system = load_system(SYSTEM_FILE)[0]
    session = open_client(router)
    monitor = start_monitor(session, system)
    events = Events(client)
    proc = None
    try:
        events.send("spot", "init_power.success.powered_on")  # step 1: init_power never started
        for skillset, transition in STEPS:  # steps 2 to 5
            events.send(skillset, transition)
        wait_until(lambda: monitor.divergences().entries and monitor.snapshot().state.seq == 5, 10, "five steps")
        once = subprocess.run([sys.executable, "-m", "skinet_cli.main", "watch", "spot_arm", "--once", "--wait", "3",
                               *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)
        view = once.stdout.splitlines()
        assert view[-2] == "divergences and manager restarts (1)", once.stdout
        assert re.fullmatch("  " + DIVERGENCE.replace("MODEL DIVERGENCE", "model divergence").format(step=1, seq=1),
                            view[-1]), once.stdout
        proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "watch", "spot_arm", "--duration", "60",
                                 *client_args(router)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        # The watch joined late: the last step's line (no predictor: its prediction stays stale), then the
        # monitor's list so far.
        first = [proc.stdout.readline().rstrip("\n") for _ in range(2)]
        assert first[0].startswith("[5] spot:stand_up.success.standing#5 | ") and \
            re.fullmatch(DIVERGENCE.format(step=1, seq=1), first[1]), first
        events.send("spot", "init_power.success.powered_on")  # step 6: spot is powered on, init_power idle
        lines = [proc.stdout.readline().rstrip("\n") for _ in range(2)]
        diverged = [line for line in lines if line.startswith("MODEL DIVERGENCE")]
        assert len(diverged) == 1 and re.fullmatch(DIVERGENCE.format(step=6, seq=6), diverged[0]), lines
    finally:
        if proc is not None:
            proc.terminate()
            proc.communicate(timeout=20)
        monitor.close()
        session.close()


def test_a_pipe_writes_a_divergence_line_after_its_steps_line() -> None:
    """The monitor's list and its verdicts travel on two keys: a violation at step 7 that arrives before
    step 7's verdicts is written after step 7's line (CI saw them the other way round), and a line whose
    step never comes is written after the hold."""
    out = io.StringIO()
    steps = StepLines(out, hold=2.0)
    steps.see((1, 6, ()), "[6] six", final=True)
    steps.note(7, "VIOLATION at step 7")
    steps.note(None, "PILOT after it")  # in order: waits behind the violation
    steps.due(time.monotonic())
    assert out.getvalue() == "[6] six\n"
    steps.see((1, 7, ()), "[7] seven", final=True)
    assert out.getvalue() == "[6] six\n[7] seven\nVIOLATION at step 7\nPILOT after it\n"
    steps.note(9, "RESTART at step 9")
    steps.due(time.monotonic())
    assert out.getvalue().endswith("PILOT after it\n")
    steps.due(time.monotonic() + 2.0)
    assert out.getvalue().endswith("PILOT after it\nRESTART at step 9\n")
