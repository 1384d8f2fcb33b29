"""The live Foxglove WebSocket server of one system (docs/foxglove.md).

:class:`FoxgloveView` follows a :class:`~services.dashboard.observer.Observer`
(a read-only Zenoh view: the router ACL's observer role is enough; it declares no
queryable and publishes nothing) and serves its updates, translated by
:class:`~services.foxglove.translate.Translator`, on the channels of
:mod:`skinet.wire.foxglove` with the ``foxglove-sdk`` WebSocket server
(``foxglove.websocket.v1``), bound to 127.0.0.1 unless told otherwise.  Foxglove
keeps no message for a late subscriber: when a client subscribes to a channel of
the live picture (state, verdicts, unsafe, state space, pilot, series) its last
message is sent again.

Cost.  The observer calls :meth:`FoxgloveView._on_updates` in Zenoh's thread with
its lock held: there the view only adds them to the round being gathered
(:class:`~services.foxglove.translate.Round`; past :data:`QUEUE` updates waiting, the
oldest are dropped and counted), and while no client subscribes to any
channel it does nothing at all: the first subscription starts the translator again
from the observer's snapshot, taken under the observer's lock so that no update is
lost or counted twice.  Translating, encoding (JSON, in Rust:
``pydantic_core.to_json``) and sending happen in a thread of this view, and a
message of a channel no client subscribes to is translated but never encoded.
That thread works in rounds, at most one per :data:`~services.foxglove.translate.ROUND` (50 a second, as a
display refreshes), each starting :data:`GATHER` after its first update (the
step's other messages join it, and the view works after the monitor's burst
rather than during it): of a channel of the live picture a round sends only its
last message (the others are counted in ``coalesced``); log lines, violations
and divergences are all sent, in order.  A flood (more than
:data:`~services.foxglove.translate.STEPS_PER_ROUND` steps in a round, 500 a second: a robot makes a few) is
folded as it comes (:class:`~services.foxglove.translate.Round`): the round keeps the last of the live picture,
every violation, divergence and pilot change, and logs one line for the steps not shown (counted in
``skipped``); while it lasts the rounds come every :data:`~services.foxglove.translate.FLOOD_ROUND`.  The board
behind the view saw every step, so no violation is lost.  Folding as the updates come, not in the round, is what
keeps a flood cheap for the monitor: a round that translated a flood's updates held the view's interpreter for
about 2 ms ten times a second, and the monitor's p99 grew by half (benchmarks/bench_latency.py,
``--dashboard-only``; docs/performance.md).  Incident bundles are written elsewhere
(:mod:`services.foxglove.bundle`) and hold every message.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from typing import Any

import foxglove
from foxglove.websocket import ChannelView, Client
from pydantic_core import to_json

from services.dashboard.board import Board, Update
from services.dashboard.observer import Observer
from services.foxglove.translate import FLOOD_ROUND, ROUND, STEPS_PER_ROUND, Out, Round, Translator
from skinet.errors import SkinetError
from skinet.wire import foxglove as fx

QUEUE = 10_000  # updates waiting for the server thread, at most
GATHER = 0.005  # seconds a round waits after its first update
HAND_BACK = 0.00005  # seconds of a round's work after which the interpreter is handed back
LATCHED = (fx.STATE, fx.VERDICTS, fx.UNSAFE, fx.STATE_SPACE, fx.PILOT, fx.SERIES)
log = logging.getLogger("skinet.foxglove")


class _Listener:
    """The server's callbacks: a subscription asks for the channel's last message again; the first one wakes the
    view up, the end of the last one puts it to sleep."""

    def __init__(self, view: FoxgloveView):
        self.view = view

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.view._subscribed(channel.topic)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        self.view._unsubscribed()


class FoxgloveView:
    """Serves ``observer``'s system on ``host:port`` (0: a free port) until :meth:`close`."""

    def __init__(self, observer: Observer, host: str = "127.0.0.1", port: int = 8765):
        self.observer = observer
        self.translator = Translator(observer.name)
        self.dropped = 0
        self.sent = 0
        self.caught_up = 0  # times the view woke up from the observer's snapshot
        self.translated = 0  # observer updates translated
        self.coalesced = 0  # messages of the live picture superseded within a round, not sent
        self.skipped = 0  # steps of a flood not shown (Round)
        self._handed = 0.0  # when the round's thread last let the interpreter's other threads in
        self._context = foxglove.Context()
        self._channels = {spec.topic: foxglove.Channel(spec.topic, schema=spec.schema, context=self._context)
                          for spec in fx.channels()}
        self._last: dict[str, tuple[dict[str, Any], int]] = {}
        self._queue: collections.deque[Round | str | tuple[str, Update]] = collections.deque()
        self._waiting = 0  # updates in the queue's rounds
        self._length = ROUND  # seconds of the round being gathered
        self._cond = threading.Condition()
        self._closed = False
        self._subscriptions = 0  # (client, channel) pairs subscribed now
        self._idle = True  # no client subscribes to any channel: updates are dropped at once
        self.busy = False  # the view's thread is translating or sending what it took from the queue
        observer.listen(self._on_updates)  # before the server: a first subscription finds it listening
        try:
            self.server = foxglove.start_server(name=f"SkiNet Live {observer.name}", host=host, port=port,
                                                context=self._context, server_listener=_Listener(self))
        except Exception as exc:  # the SDK raises its own error types (port in use, bad address)
            observer.unlisten(self._on_updates)
            raise SkinetError(f"cannot serve Foxglove on {host}:{port}: {exc}") from None
        self.host = host
        self.port = self.server.port
        self._thread = threading.Thread(target=self._run, name="skinet-foxglove", daemon=True)
        self._thread.start()

    @property
    def idle(self) -> bool:
        """Whether no client subscribes to any channel (updates are dropped)."""
        return self._idle

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def close(self) -> None:
        self.observer.unlisten(self._on_updates)
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout=5)
        self.server.stop()

    # -- from the observer (its lock held: never block) -----------------------------------

    def _on_updates(self, updates: list[Update]) -> None:
        if self._idle:
            return
        with self._cond:
            gathered = self._queue[-1] if self._queue else None
            if not isinstance(gathered, Round):  # a catch-up or a subscription's repeat ends the round before it
                gathered = Round(STEPS_PER_ROUND, self._length)
                self._queue.append(gathered)
            before = len(gathered.updates)
            gathered.add(updates)
            self._waiting += len(gathered.updates) - before
            while self._waiting > QUEUE:  # the view's thread stalled: its oldest updates go
                oldest = next(item for item in self._queue if isinstance(item, Round) and item.updates)
                oldest.updates.pop(0)
                self._waiting -= 1
                self.dropped += 1
            self._cond.notify_all()

    def _put(self, item: str | tuple[str, Update]) -> None:
        with self._cond:
            self._queue.append(item)
            self._cond.notify_all()

    # -- from the server's callbacks ----------------------------------------------------------

    # Both under the observer's lock: an update comes either before the snapshot (in it) or after it (queued).

    def _subscribed(self, topic: str) -> None:
        def wake(board: Board) -> None:
            self._subscriptions += 1
            if self._idle:
                self._idle = False
                self._put(("snapshot", board.snapshot()))
        self.observer.read(wake)
        if topic in LATCHED:
            self._put(topic)

    def _unsubscribed(self) -> None:
        def sleep(_board: Board) -> None:
            self._subscriptions = max(0, self._subscriptions - 1)  # a client gone: one call per subscription
            self._idle = self._subscriptions == 0
            if self._idle:  # nobody to send to: what waits is dropped, the next client starts from a snapshot
                with self._cond:
                    self._queue.clear()
                    self._waiting = 0
        self.observer.read(sleep)

    # -- the server thread ------------------------------------------------------------------

    def _run(self) -> None:
        next_round = 0.0
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
            # The rest of the step's messages gather meanwhile, and the view works after the monitor's burst.
            time.sleep(max(GATHER, next_round - time.monotonic()))
            with self._cond:
                items = list(self._queue)
                self._queue.clear()
                self._waiting = 0
                self.busy = bool(items)
                flood = any(isinstance(item, Round) and item.flood for item in items)
                self._length = FLOOD_ROUND if flood else ROUND
            next_round = time.monotonic() + self._length
            outs: list[Out] = []
            self._handed = time.perf_counter()
            for item in items:
                if isinstance(item, str):  # a subscription: the channel's last message again, unless newer is due
                    last = self._last.get(item)
                    if last is not None and all(topic != item for topic, _m, _t in outs):
                        outs.append((item, *last))
                elif isinstance(item, tuple):
                    self._send(outs)
                    outs = []
                    self._catch_up(item[1])
                elif not self._idle:  # else the last client left meanwhile: nobody to translate for
                    shown = item.shown()
                    if item.flood:
                        self.skipped += shown[-1]["steps"]
                    self.translated += len(shown)
                    outs += self.translator.feed(shown)
                self._hand_back()
            self._send(outs)
            self.busy = False

    def _hand_back(self) -> None:
        """Let the interpreter's other threads in after :data:`HAND_BACK` of work: in a process that also runs a
        monitor (a view on its session) a round held at once would keep the monitor waiting up to Python's 5 ms
        switch interval."""
        if time.perf_counter() - self._handed > HAND_BACK:
            time.sleep(0)
            self._handed = time.perf_counter()

    def _catch_up(self, snapshot: Update) -> None:
        """Start again from the observer's ``snapshot``: the translator's counts and the channels' last messages
        (sent on subscription); violations, divergences and log lines of before are not sent again."""
        self.caught_up += 1
        self.translator = Translator(self.observer.name)
        self._last = {topic: (message, t) for topic, message, t in self.translator.snapshot(snapshot)
                      if topic in LATCHED}

    def _send(self, outs: list[Out]) -> None:
        """Send one round's messages: of a channel of the live picture only its last (:data:`LATCHED`), of the
        others (log lines, violations, divergences) every one, in order."""
        last = {topic: i for i, (topic, _m, _t) in enumerate(outs) if topic in LATCHED}
        for i, (topic, message, t) in enumerate(outs):
            if topic in LATCHED:
                if last[topic] != i:
                    self.coalesced += 1
                    continue
                self._last[topic] = (message, t)
            if self._channels[topic].has_sinks():  # else nobody subscribes: not even encoded
                self._log(topic, message, t)
                self._hand_back()

    def _log(self, topic: str, message: dict[str, Any], t: int) -> None:
        try:
            self._channels[topic].log(to_json(message), log_time=t)
            self.sent += 1
        except Exception:  # never let one message stop the view
            log.exception("cannot send a message on %s", topic)
