"""Whether the bridge's session still reaches a router: what the robot publishes meanwhile is lost (docs/semantics.md §7).

The robot's topics are volatile (a manager's statuses, a lifecycle node's
transition events, a bound topic's samples): a bridge whose session has lost every
router misses them for good, and its last status of each skillset may be outdated
when the link comes back.  :func:`watch_link` looks at the session's routers every
:data:`POLL` seconds and tells the bridge when the link is cut (``on_cut``) and when
it is back (``on_back``); a link replaced by another router at once (a restart
faster than a poll) counts as a cut too.  Cost: one look at the routers per poll.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import zenoh

log = logging.getLogger("skinet.bridge_ros2")

POLL = 0.2  # seconds between looks at the session's routers (a client reconnects about 2 s after a restart)


def watch_link(session: zenoh.Session, stop: threading.Event, on_cut: Callable[[], None],
               on_back: Callable[[], None], poll: float = POLL) -> None:
    """Call ``on_cut`` when ``session`` lost every router it had, ``on_back`` when one is there again;
    returns when ``stop`` is set or the session closes (run it on a thread of its own)."""
    routers: set[str] = set()
    cut = False
    while True:  # a first look at once: the link may be cut within the first poll
        try:
            now = {str(z) for z in session.info.routers_zid()}
        except zenoh.ZError:  # the session is closing
            return
        if routers and not cut and (not now or not now & routers):
            cut = True
            on_cut()
        if now and cut:
            cut = False
            on_back()
        if now:
            routers = now
        if stop.wait(poll):
            return


__all__ = ["POLL", "watch_link"]
