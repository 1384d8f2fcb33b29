"""Services start without the ROS type library (issue 33 item 4; docs/performance.md).

``rosbags`` costs 0.3-0.5 s to import; only the code that makes a type store, or
reads a bag, imports it.  A service's help, and a monitor's whole life on a system
bound to plain ROS 2 interfaces (examples/nav2), never need it.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Callable

import pytest
import zenoh

from skinet.wire import keys
from tests.services.conftest import REPO, LivelinessWatch, client_args

SERVICES = sorted(p.name for p in (REPO / "services").iterdir() if (p / "__main__.py").is_file())
# Runs ``python -m MODULE ARGS...`` (sys.argv[1:]), then prints the rosbags modules it imported, however it ends.
ROSBAGS = ("import atexit, runpy, sys\n"
           "atexit.register(lambda: print(sorted(m for m in sys.modules if m.split('.')[0] == 'rosbags')))\n"
           "sys.argv = sys.argv[1:]\n"
           "runpy.run_module(sys.argv[0], run_name='__main__', alter_sys=True)\n")


def test_every_service_is_checked() -> None:
    assert SERVICES == ["bridge_ros2", "dashboard", "foxglove", "monitor", "pilot", "predictor", "secrets",
                        "simulator"]


@pytest.mark.parametrize("service", SERVICES)
def test_help_imports_no_ros_type_library(service: str) -> None:
    done = subprocess.run([sys.executable, "-c", ROSBAGS, f"services.{service}", "--help"], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    assert done.stdout.startswith(f"usage: python -m services.{service} ")
    assert done.stdout.splitlines()[-1] == "[]"


def test_monitor_of_a_bound_system_never_imports_it(router: str, client: zenoh.Session,
                                                    watch: Callable[[zenoh.Session, str], LivelinessWatch]) -> None:
    """Load (the binding's commanded resources are read), serve, stop: no type store on the way."""
    alive = watch(client, keys.alive("nav2", "monitor", "*"))
    proc = subprocess.Popen([sys.executable, "-c", ROSBAGS, "services.monitor", "examples/nav2/nav2.toml",
                             *client_args(router), "--id", "m1"], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        alive.wait(lambda tokens: keys.alive("nav2", "monitor", "m1") in tokens)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "monitoring nav2" in err
    assert out.splitlines()[-1] == "[]"
