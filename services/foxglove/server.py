"""The live Foxglove WebSocket server of one system (docs/foxglove.md).

:class:`FoxgloveView` follows a :class:`~services.dashboard.observer.Observer`
(a read-only Zenoh view: the router ACL's observer role is enough; it declares no
queryable and publishes nothing) and serves its updates, translated by
:class:`~services.foxglove.translate.Translator`, on the channels of
:mod:`skinet.wire.foxglove` with the ``foxglove-sdk`` WebSocket server
(``foxglove.websocket.v1``), bound to 127.0.0.1 unless told otherwise.  Foxglove
keeps no message for a late subscriber: when a client subscribes to a channel of
the live picture (state, verdicts, unsafe, state space, pilot, series) its last
message is sent again.  Messages are logged from a thread of this view, never
from Zenoh's: a slow client costs the observer nothing.  Cost: O(1) per update
beyond the translation; the queue between the observer and the server is bounded
(:data:`QUEUE`): past it the oldest updates are dropped and counted.
"""

from __future__ import annotations

import collections
import logging
import threading
from typing import Any

import foxglove
from foxglove.websocket import ChannelView, Client

from services.dashboard.board import Update
from services.dashboard.observer import Observer
from services.foxglove.translate import Out, Translator
from skinet.errors import SkinetError
from skinet.wire import foxglove as fx

QUEUE = 10_000  # updates waiting for the server thread
LATCHED = (fx.STATE, fx.VERDICTS, fx.UNSAFE, fx.STATE_SPACE, fx.PILOT, fx.SERIES)
log = logging.getLogger("skinet.foxglove")


class _Listener:
    """The server's callbacks: a subscription asks for the channel's last message again."""

    def __init__(self, view: FoxgloveView):
        self.view = view

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.view._resend(channel.topic)


class FoxgloveView:
    """Serves ``observer``'s system on ``host:port`` (0: a free port) until :meth:`close`."""

    def __init__(self, observer: Observer, host: str = "127.0.0.1", port: int = 8765):
        self.observer = observer
        self.translator = Translator(observer.name)
        self.dropped = 0
        self.sent = 0
        self._context = foxglove.Context()
        self._channels = {spec.topic: foxglove.Channel(spec.topic, schema=spec.schema, context=self._context)
                          for spec in fx.channels()}
        self._last: dict[str, tuple[dict[str, Any], int]] = {}
        self._queue: collections.deque[list[Update] | str] = collections.deque()
        self._cond = threading.Condition()
        self._closed = False
        try:
            self.server = foxglove.start_server(name=f"SkiNet Live {observer.name}", host=host, port=port,
                                                context=self._context, server_listener=_Listener(self))
        except Exception as exc:  # the SDK raises its own error types (port in use, bad address)
            raise SkinetError(f"cannot serve Foxglove on {host}:{port}: {exc}") from None
        self.host = host
        self.port = self.server.port
        self._thread = threading.Thread(target=self._run, name="skinet-foxglove", daemon=True)
        self._thread.start()
        self._put(observer.listen(self._on_updates))

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
        self._put(updates)

    def _put(self, item: list[Update] | Update | str) -> None:
        with self._cond:
            if len(self._queue) >= QUEUE:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append(item)  # type: ignore[arg-type]
            self._cond.notify_all()

    def _resend(self, topic: str) -> None:
        if topic in LATCHED:
            self._put(topic)

    # -- the server thread ------------------------------------------------------------------

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                item = self._queue.popleft()
            if isinstance(item, str):
                last = self._last.get(item)
                if last is not None:
                    self._channels[item].log(last[0], log_time=last[1])
                continue
            if isinstance(item, dict):  # the snapshot the view starts from
                outs = self.translator.snapshot(item)
            else:
                outs = self.translator.feed(item)
            self._send(outs)

    def _send(self, outs: list[Out]) -> None:
        for topic, message, t in outs:
            if topic in LATCHED:
                self._last[topic] = (message, t)
            try:
                self._channels[topic].log(message, log_time=t)
                self.sent += 1
            except Exception:  # never let one message stop the view
                log.exception("cannot send a message on %s", topic)
