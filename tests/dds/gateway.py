"""The real ``zenoh-plugin-ros2dds`` in a router process, on a private DDS domain over loopback.

:class:`Gateway` starts ``skinet-ros2dds-bridge`` (``native/ros2dds_bridge``, the
plugin 1.10.2 linked statically, built by :mod:`native_build`) as a Zenoh router
listening on a free port of 127.0.0.1, its DDS participant on ``domain`` with the
unicast loopback configuration of :func:`services.simulator.dds.loopback_config`
and ``ROS_DISTRO`` set (the plugin reads the ``ros_discovery_info`` GIDs by it).
"""

from __future__ import annotations

import os
import random
import subprocess
import threading
import time
from pathlib import Path

from services.simulator.dds import loopback_config
from tests.loopback import free_port


def free_domain() -> int:
    """A DDS domain id unlikely to be used by another test run on the machine (ports 7400 + 250 * id)."""
    return random.randint(20, 220)


class Gateway:
    """One plugin process; ``endpoint`` is its Zenoh listener; :meth:`close` stops it."""

    def __init__(self, binary: Path, workdir: Path, *, domain: int, distro: str, namespace: str = "/",
                 connect: str | None = None):
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.domain = domain
        config = workdir / f"ros2dds-{domain}-{distro}-{self.endpoint.rsplit(':', 1)[1]}.json5"
        links = f'connect: {{ endpoints: ["{connect}"] }},' if connect else ""
        config.write_text(f"""{{
  mode: "router",
  listen: {{ endpoints: ["{self.endpoint}"] }},
  {links}
  scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }},
  plugins: {{ ros2dds: {{ domain: {domain}, namespace: "{namespace}" }} }},
}}
""")
        env = {**os.environ, "CYCLONEDDS_URI": loopback_config(), "ROS_DISTRO": distro,
               "RUST_LOG": os.environ.get("SKINET_TEST_RUST_LOG", "warn")}
        self.log: list[str] = []
        self._ready = threading.Event()
        self.proc = subprocess.Popen([str(binary), "-c", str(config)], env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if not self._ready.wait(30):
            self.close()
            raise RuntimeError("zenoh-plugin-ros2dds did not start:\n" + self.output())
        time.sleep(0.2)  # the listener is up a moment after the plugin

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.log.append(line.rstrip())
            if "running" in line and line.startswith("zenoh-plugin-ros2dds"):
                self._ready.set()

    def output(self) -> str:
        return "\n".join(self.log)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(5)
