"""The simulated robot of ``skinet run SYSTEM.toml --simulate``, with its bridge, on the run's session.

The robot is the one ``python -m services.simulator SYSTEM.toml --self-ending`` serves
(:func:`services.simulator.world.simulated_robot`, :func:`~services.simulator.world.self_ending`):
the system's skillset managers, or the action servers, lifecycle nodes and topics of its
bindings, whose skills end by themselves.  The bridge turns what it publishes into canonical
events, as ``python -m services.bridge_ros2`` would beside a real robot; so the monitor, the
predictor and the pilot of ``skinet run`` see a robot, and ``skinet goal ... --drive`` drives it
(docs/pilot.md, *Try the pilot in one command*).  Cost: the simulator's and the bridge's, one
worker thread each.
"""

from __future__ import annotations

from collections.abc import Mapping

import zenoh

from services.bridge_ros2.bound_live import start_bound_bridge
from services.bridge_ros2.service import start_bridge
from services.simulator.world import SelfEnding, self_ending, simulated_robot
from skinet.pilot.run import Outcomes
from skinet.ros.keys import KeyStyle
from skinet.system.load import load_bindings
from skinet.system.model import System


class SimulatedRobot:
    """The robot and its bridge (:func:`start_simulated_robot`); :meth:`close` stops both."""

    def __init__(self, robot: SelfEnding, bridge: object):
        self.robot, self.bridge = robot, bridge

    def close(self) -> None:
        self.bridge.close()  # type: ignore[attr-defined]
        self.robot.close()


def start_simulated_robot(session: zenoh.Session, system: System, typemap: Mapping[str, str], *, instance: str,
                          style: KeyStyle = KeyStyle(), duration: float = 1.0, failure_rate: float = 0.0,
                          seed: int = 0) -> SimulatedRobot:
    """``system``'s simulated robot on ``session``, each skill ending ``duration`` seconds after it starts, in a
    failure mode with probability ``failure_rate`` (drawn from ``seed``), else its first success mode; and a
    bridge of instance ``instance`` on the keys of ``style``.  Raises ``ValueError`` for a system the simulator
    cannot play (managers and bindings both; a bound topic without a first sample)."""
    bindings, _ = load_bindings(system)
    robot = self_ending(simulated_robot(session, system, typemap, bindings, style),
                        Outcomes(system, failure_rate=failure_rate, seed=seed), duration)
    try:
        bridge: object = (start_bound_bridge(session, system, bindings, style=style, instance_id=instance) if bindings
                          else start_bridge(session, system, typemap, style=style, instance_id=instance))
    except Exception:
        robot.close()
        raise
    return SimulatedRobot(robot, bridge)


__all__ = ["SimulatedRobot", "start_simulated_robot"]
