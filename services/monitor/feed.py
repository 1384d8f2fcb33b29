"""The monitor's results in rounds on ``skinet/<system>/@feed`` (:class:`~skinet.wire.messages.ResultFeed`), for
views on the robot's own cores (docs/foxglove.md, *The monitor's feed*).

Why: a view subscribed to the monitor's five result keys is one more Zenoh delivery of each of its messages,
three or more a step.  Back to back (about 1 700 steps a second) the router's sends and the view's wake-ups,
on 2 shared cores, cost the monitor's event -> warning p99 about 17 % even for a subscriber that does nothing
with them (benchmarks/bench_latency.py, ``--views-only``).  A view shows what a display can: :class:`Feeder`
hands it the same messages in rounds, one Zenoh message per round, every
:data:`~skinet.wire.limits.FEED_ROUND` while results come.  Past :data:`~skinet.wire.limits.FEED_STEPS` steps in
a round (500 a second; a robot makes a few) the round keeps only the last result of each kind and counts the
steps it left out (the divergence list names the onset of every violation at its own step, so none is lost),
and while such a flood lasts the rounds come every :data:`~skinet.wire.limits.FEED_FLOOD_ROUND`.

The monitor hands a step's results to :meth:`Feeder.add` after its puts; a thread of the feed publishes the
round when it is due.  All this only while someone subscribes to the feed (Zenoh's matching status, told by a
listener): with no view, :meth:`Feeder.add` returns at once and nothing is gathered, encoded or sent.  A view
that subscribes gets the rounds from the next result on; it asks the monitor's keys for the last results when
it starts, and again half a second later (:data:`~services.dashboard.observer.FOLLOW_UP`), which covers the
results the monitor made before it learnt of the subscriber.  ``seq`` counts the rounds published, so a
subscriber that sees it jump knows it lost one (the rounds are sent with congestion control ``DROP``: the monitor
never waits for a view).  The messages are spliced into the round as they were published (msgpack in msgpack),
never decoded.

Cost: with no subscriber, one attribute read per call in the monitor's thread.  With one, in the monitor's
thread, one list append per message under the feed's lock and one wake-up of the feed's thread per round; in
that thread, per round, the encoding of its messages' headers and one put.  The round's memory is bounded: at
most :data:`~skinet.wire.limits.FEED_STEPS` steps' messages, then one of each kind.
"""

from __future__ import annotations

import logging
import threading
import time

import msgpack
import zenoh

from skinet.wire import keys
from skinet.wire.limits import FEED_FLOOD_ROUND, FEED_ROUND, FEED_STEPS
from skinet.wire.messages import SCHEMA_VERSION

KINDS = ("divergences", "state", "verdicts", "unsafe", "state_space")  # a folded round's order: the list first
log = logging.getLogger("skinet.monitor")


class Feeder:
    """The feed of the monitor ``instance`` of ``system`` on ``session``; :meth:`close` ends it."""

    def __init__(self, session: zenoh.Session, system: str, instance: str):
        self._system, self._instance = system, instance
        self._pub = session.declare_publisher(keys.feed(system), congestion_control=zenoh.CongestionControl.DROP)
        self._cond = threading.Condition(threading.Lock())
        self._results: list[tuple[str, bytes]] = []  # the round's, in order, up to FEED_STEPS steps
        self._last: dict[str, bytes] = {}  # past FEED_STEPS steps: the last of each kind
        self._steps = 0  # steps (states) in the round
        self._since: float | None = None  # monotonic time of the round's first result; None: the round is empty
        self._length = FEED_ROUND  # seconds of the round being gathered
        self._closed = False
        self.seq = 0  # rounds published
        self.skipped = 0  # steps left out of the rounds published
        self.unheard = 0  # rounds gathered while someone subscribed, nobody subscribing when due: not published
        self.heard = False  # someone subscribes to the feed (Zenoh's matching status): else add() does nothing
        self._listener = self._pub.declare_matching_listener(self._on_matching)
        self.heard = self._pub.matching_status.matching  # the listener tells changes only
        self._thread = threading.Thread(target=self._run, name="skinet-monitor-feed", daemon=True)
        self._thread.start()

    def add(self, *results: tuple[str, bytes]) -> None:
        """Results the monitor published at once (a step's state, verdicts and report), as (kind, payload)."""
        if not self.heard:
            return
        with self._cond:
            if self._closed:
                return
            for kind, payload in results:
                if kind == "state":
                    self._steps += 1
                    if self._steps == FEED_STEPS + 1:  # a flood: from now on the last of each kind
                        self._last = dict(self._results)
                        self._results = []
                if self._steps > FEED_STEPS:
                    self._last[kind] = payload
                else:
                    self._results.append((kind, payload))
            if self._since is None:
                self._since = time.monotonic()
                self._cond.notify()

    def _on_matching(self, status: zenoh.MatchingStatus) -> None:
        self.heard = status.matching

    def close(self) -> None:
        """Stop the feed's thread (what the round holds is not sent) and undeclare its publisher."""
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join(timeout=2)
        self._listener.undeclare()
        self._pub.undeclare()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._closed:  # add() wakes it at a round's first result, close() at once
                    if self._since is None:
                        self._cond.wait()
                        continue
                    left = self._since + self._length - time.monotonic()
                    if left <= 0:
                        break
                    self._cond.wait(left)
                if self._closed:
                    return
                flood = self._steps > FEED_STEPS
                results = [(k, self._last[k]) for k in KINDS if k in self._last] if flood else self._results
                skipped, length = (self._steps - 1 if flood else 0), self._length
                self._results, self._last, self._steps, self._since = [], {}, 0, None
                self._length = FEED_FLOOD_ROUND if flood else FEED_ROUND
            try:
                self._publish(results, skipped, length)
            except zenoh.ZError as exc:  # the session closes under a monitor being closed
                log.debug("the monitor's feed stopped: %s", exc)
                return

    def _publish(self, results: list[tuple[str, bytes]], skipped: int, length: float) -> None:
        """One round as a :class:`~skinet.wire.messages.ResultFeed`, when someone subscribes to the feed."""
        if not self.heard:
            self.unheard += 1
            return
        self.seq += 1
        self.skipped += skipped
        self._pub.put(pack(self._system, self._instance, self.seq, length, skipped, results))


def pack(system: str, instance: str, seq: int, length: float, skipped: int, results: list[tuple[str, bytes]]) -> bytes:
    """A :class:`~skinet.wire.messages.ResultFeed` whose messages are ``results``' payloads as they are (each the
    msgpack of a map: spliced in, a map within the round's map)."""
    head = {"v": SCHEMA_VERSION, "system": system, "monitor": instance, "seq": seq, "round": length,
            "skipped": skipped}
    packer = msgpack.Packer(use_bin_type=True)
    parts = [packer.pack_map_header(len(head) + 1)]
    for name, value in head.items():
        parts += (packer.pack(name), packer.pack(value))
    parts += (packer.pack("results"), packer.pack_array_header(len(results)))
    for kind, payload in results:
        parts += (packer.pack_map_header(2), packer.pack("kind"), packer.pack(kind), packer.pack("message"), payload)
    return b"".join(parts)
