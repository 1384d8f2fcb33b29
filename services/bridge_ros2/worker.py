"""The bridge's one derivation thread: jobs in arrival order, events published in order (docs/semantics.md §1, §7).

Zenoh callbacks only queue a job (a message to derive, a reply, a resync mark);
the worker runs the jobs one after the other under :attr:`Worker.lock`, takes the
events whose turn has come from the shared :class:`~services.bridge_ros2.order.Order`
and publishes each on its skillset's publisher (outside the lock: a publication
that blocks never blocks a resync answer).  When ``python -m services.bridge_ros2``
serves managers and bound skillsets, both bridges queue their jobs here, so their
events leave in the order their messages arrived, across both kinds.  A *timer*
(a feed's ``deadline`` and ``expire``) releases what waits past its hold time; a
*follow-up* runs after each job (the bridge's heartbeat when what it says changed).
The bridges sharing a worker are one source for the monitor: one ``epoch`` (this
run), one liveliness token and one heartbeat listing all their skillsets
(:meth:`Worker.beacon`).

Cost: one queue hand-off per message; the thread sleeps until a job or a deadline.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from services.bridge_ros2.order import Order
from services.common.heartbeat import Beat, HeartbeatPublisher, Pending
from services.common.zenoh_config import undeclare
from skinet.wire import keys
from skinet.wire.codec import encode
from skinet.wire.messages import CanonicalEvent

log = logging.getLogger("skinet.bridge_ros2")

Job = Callable[[], list[CanonicalEvent] | None]


class Worker:
    """One thread deriving for one or more bridges of a process; see the module docstring."""

    def __init__(self, name: str = "bridge_ros2") -> None:
        self.epoch = time.time_ns() // 1_000_000  # the run of the bridges sharing it: their events' epoch
        self.order = Order()
        self.lock = threading.Condition()  # held while a job runs; notified after each one
        self.publishers: dict[str, Any] = {}  # skillset -> its events' publisher
        self._timers: list[tuple[Callable[[], float | None], Job]] = []
        self._follow_ups: list[Callable[[], None]] = []
        self._queue: queue.SimpleQueue[Job | None] = queue.SimpleQueue()
        self._beacon: tuple[HeartbeatPublisher, Any] | None = None  # the heartbeat and the token
        self._beacon_users = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def beacon(self, session: zenoh.Session, system: str, source: str, instance: str, beat: Beat,
               pending: Pending) -> HeartbeatPublisher:
        """The heartbeat (and liveliness token ``keys.alive(system, "bridge_ros2", instance)``) of the bridges
        sharing this worker, with ``beat`` and ``pending`` added; declared by the first caller."""
        if self._beacon is None:
            token = keys.alive(system, "bridge_ros2", instance)
            declared = session.liveliness().declare_token(token)
            self._beacon = (HeartbeatPublisher(session, system, source, self.epoch, token, beat, pending=pending),
                            declared)
        else:
            if self._beacon[0].source != source:
                raise ValueError(f"bridges of one worker publish as one source ({self._beacon[0].source}), not "
                                 f"{source}")
            self._beacon[0].add(beat, pending)
        self._beacon_users += 1
        return self._beacon[0]

    def release(self, beat: Beat) -> None:
        """A bridge stops: its skillsets leave the heartbeat; the last one undeclares heartbeat and token."""
        if self._beacon is None:
            return
        self._beacon_users -= 1
        heartbeat, token = self._beacon
        heartbeat.remove(beat)
        if self._beacon_users <= 0:
            self._beacon = None
            heartbeat.close()
            undeclare(token)

    def put(self, job: Job) -> None:
        """Run ``job`` after every job queued before it (from any thread)."""
        self._queue.put(job)

    def add_timer(self, deadline: Callable[[], float | None], expire: Job) -> None:
        """Run ``expire`` when the monotonic time ``deadline()`` (None: no deadline) has come."""
        self._timers.append((deadline, expire))

    def add_follow_up(self, follow_up: Callable[[], None]) -> None:
        """Call ``follow_up`` after each job, outside the lock."""
        self._follow_ups.append(follow_up)

    def _deadline(self) -> float | None:
        return min((d for d in (deadline() for deadline, _ in self._timers) if d is not None), default=None)

    def _run(self) -> None:
        while True:
            deadline = self._deadline()
            try:
                job = self._queue.get(timeout=None if deadline is None else max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                job = self._expire  # a deadline has come
            if job is None:
                return
            events: list[CanonicalEvent] = []
            try:
                with self.lock:
                    events = (job() or []) + self.order.drain()
            except Exception:  # a bug must not stop the bridge (docs/semantics.md §7)
                log.exception("failed to derive a message")
            for ev in events:
                try:
                    self.publishers[ev.skillset].put(encode(ev))
                except Exception:
                    log.exception("cannot publish an event of %s", ev.skillset)
            for follow_up in self._follow_ups:
                try:
                    follow_up()
                except Exception:
                    log.exception("failed after a message")
            with self.lock:
                self.lock.notify_all()

    def _expire(self) -> list[CanonicalEvent]:
        now = time.monotonic()
        out: list[CanonicalEvent] = []
        for deadline, expire in self._timers:
            due = deadline()
            if due is not None and due <= now:
                out += expire() or []
        return out

    def wait_idle(self, timeout: float = 5.0) -> bool:
        """Wait until every job queued so far has run and its events were published."""
        done = threading.Event()
        self._queue.put(lambda: done.set() or [])
        return done.wait(timeout)

    def close(self, timeout: float = 5.0) -> None:
        """Run what is queued, then stop."""
        self._queue.put(None)
        self._thread.join(timeout)


__all__ = ["Job", "Worker"]
