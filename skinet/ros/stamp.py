"""ROS 2 ``builtin_interfaces/msg/Time`` from seconds, within its int32 seconds (docs/robot.md).

A ``Time``'s ``sec`` is an int32: a stamp past 2038-01-19 03:14:07 UTC (or before
1901-12-13 20:45:52 UTC) has no encoding, and CDR serialisation fails on it.  :func:`ros_time`
clamps such a stamp to the nearest one that exists and says so, so that a simulated
robot with a clock far ahead goes on publishing (sequence numbers, not stamps, order the
monitor's history: docs/operator.md) with a warning instead of stopping.

Cost: O(1).
"""

from __future__ import annotations

import math
import time

SEC_MIN, SEC_MAX = -(2**31), 2**31 - 1


def ros_time(t: float) -> tuple[int, int, str]:
    """(sec, nanosec, problem) of ``t`` seconds since the epoch; ``problem`` is "" when ``t`` fits, else why
    it was clamped (a non-finite ``t`` too)."""
    if not math.isfinite(t):
        return 0, 0, f"stamp {t} is not a time: 0 (1970-01-01) sent instead"
    if t >= SEC_MAX + 1 or t < SEC_MIN:
        edge = SEC_MAX if t > 0 else SEC_MIN
        return edge, 999_999_999 if t > 0 else 0, (
            f"stamp {t:.0f} s is past the int32 seconds of ROS Time ({_utc(edge)}): clamped to it")
    sec = math.floor(t)
    nanosec = min(int(round((t - sec) * 1e9)), 999_999_999)
    return sec, nanosec, ""


def _utc(sec: int) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(sec))
