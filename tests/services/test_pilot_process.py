"""``python -m services.pilot`` as a process (issue 24): a one-line error on a bad system file, a
liveliness token and a status on ``get`` with no monitor running, a clean stop on SIGTERM."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import PilotStatus
from tests.services.conftest import REPO


def test_a_bad_system_file_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[system]\nname = "x y"\n')
    out = subprocess.run([sys.executable, "-m", "services.pilot", str(bad)], cwd=REPO, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 1
    assert out.stderr.count("\n") == 1 and out.stderr.startswith(f"{bad}:"), out.stderr


def test_the_pilot_process_waits_for_a_monitor_and_stops_cleanly(spawn, zenoh_args, client, watch) -> None:
    tokens = watch(client, keys.alive("spot_arm", "pilot", "*"))
    proc = spawn("services.pilot", str(REPO / "skillsets" / "spot_arm.toml"), "--instance", "cli",
                 "--response-timeout", "2", *zenoh_args)
    tokens.wait_for(keys.alive("spot_arm", "pilot", "cli"), timeout=30)
    [reply] = list(client.get(keys.pilot_status("spot_arm"), timeout=5.0))
    status = decode(reply.ok.payload.to_bytes(), PilotStatus)
    assert (status.pilot, status.state, status.reason) == (
        "cli", "waiting for monitor", "no monitor of spot_arm is running (no token on skinet/spot_arm/alive/monitor/*)")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=10) == 0
    tokens.wait_gone(keys.alive("spot_arm", "pilot", "cli"))
