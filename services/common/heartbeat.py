"""A publisher of canonical events says it is alive: :class:`Heartbeat` every 0.5 s (SPEC §7, honest live state).

zenoh.ext's advanced publisher sends heartbeats of its own, but they are internal
to its subscriber (miss detection) and say nothing to the application.  This one
is for the monitor: it names the source and epoch of the events, the liveliness
token the publisher holds, and per skillset the seq of its last event and whether
its manager is present, on ``keys.heartbeat(system, source)``.  A monitor that
hears nothing from a source for its bound (2 s by default, four periods) counts
that source's skillsets as ``lost``.  Cost: one small put per period.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import zenoh

from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.messages import Heartbeat, HeartbeatSkillset

log = logging.getLogger("skinet.heartbeat")

PERIOD = 0.5  # seconds between heartbeats


class HeartbeatPublisher:
    """Publishes ``beat()`` (skillset -> :class:`HeartbeatSkillset`) every ``period`` seconds from a thread."""

    def __init__(self, session: zenoh.Session, system: str, source: str, epoch: int, token: str,
                 beat: Callable[[], dict[str, HeartbeatSkillset]], period: float = PERIOD):
        self.system, self.source, self.epoch, self.token, self.period = system, source, epoch, token, period
        self._beat = beat
        # DROP: a heartbeat stuck behind a dead link is worth nothing; the next one replaces it.
        self._pub = session.declare_publisher(keys.heartbeat(system, source), express=True)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="skinet-heartbeat", daemon=True)
        self._thread.start()

    def message(self) -> Heartbeat:
        return Heartbeat(system=self.system, source=self.source, epoch=self.epoch, period=self.period,
                         token=self.token, skillsets=self._beat())

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._pub.put(encode(self.message()))
            except zenoh.ZError:
                return  # the session closed under us
            except Exception:  # a bug must not stop the publisher's process
                log.exception("cannot publish a heartbeat")
            self._stop.wait(self.period)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        try:
            self._pub.undeclare()
        except zenoh.ZError:
            pass
