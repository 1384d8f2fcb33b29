"""A small client of the ``foxglove.websocket.v1`` protocol (``foxglove.sdk.v1`` now) (aiohttp's WebSocket client), for tests.

It connects with the protocol's subprotocol, keeps the channels the server
advertises, subscribes to all of them, and decodes every message-data frame
(opcode 1, subscription id u32 LE, log time u64 LE, then the payload) as JSON,
validated against its channel's advertised JSON Schema.  It runs its own event
loop in a thread; :meth:`wait` blocks until a condition on the received messages holds.
"""

from __future__ import annotations

import asyncio
import json
import struct
import threading
import time
from collections.abc import Callable
from typing import Any

import aiohttp
import jsonschema
import pytest

# foxglove-sdk 0.30 answers only the protocol's current name, foxglove.sdk.v1 (same frames as
# foxglove.websocket.v1, which it refuses with HTTP 400); the client offers both, as Foxglove does.
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")


class FoxgloveClient:
    def __init__(self, url: str, timeout: float = 15.0):
        self.url = url
        self.channels: dict[int, dict[str, Any]] = {}  # channel id -> advertised channel
        self.messages: list[tuple[str, int, dict[str, Any]]] = []  # (topic, log time ns, message)
        self.invalid: list[str] = []
        self.server_info: dict[str, Any] | None = None
        self.protocol: str | None = None  # the subprotocol the server chose
        self._subs: dict[int, int] = {}  # subscription id -> channel id
        self._cond = threading.Condition()
        self._loop = asyncio.new_event_loop()
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._loop.run_until_complete, args=(self._main(timeout),),
                                        daemon=True)
        self._thread.start()

    def topics(self) -> dict[str, dict[str, Any]]:
        with self._cond:
            return {c["topic"]: c for c in self.channels.values()}

    def on(self, topic: str) -> list[dict[str, Any]]:
        with self._cond:
            return [m for t, _, m in self.messages if t == topic]

    def wait(self, predicate: Callable[[FoxgloveClient], object], what: str, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                self._cond.release()
                try:
                    if predicate(self):
                        return
                finally:
                    self._cond.acquire()
                left = deadline - time.monotonic()
                if left <= 0:
                    pytest.fail(f"the Foxglove client never saw {what} within {timeout} s")
                self._cond.wait(min(left, 0.5))

    def close(self) -> None:
        if self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(timeout=5)

    async def _main(self, timeout: float) -> None:
        self._stop = asyncio.Event()
        deadline = time.monotonic() + timeout
        async with aiohttp.ClientSession() as http:
            while True:  # the server process may still be starting
                try:
                    ws = await http.ws_connect(self.url, protocols=SUBPROTOCOLS)
                    break
                except aiohttp.ClientError:
                    if time.monotonic() > deadline:
                        raise
                    await asyncio.sleep(0.1)
            self.protocol = ws.protocol
            reader = asyncio.ensure_future(self._read(ws))
            await self._stop.wait()
            reader.cancel()
            await ws.close()

    async def _read(self, ws: aiohttp.ClientWebSocketResponse) -> None:
        async for msg in ws:
            if msg.type == aiohttp.WSMsgType.TEXT:
                op = json.loads(msg.data)
                if op["op"] == "serverInfo":
                    self.server_info = op
                elif op["op"] == "advertise":
                    subs = []
                    with self._cond:
                        for ch in op["channels"]:
                            self.channels[ch["id"]] = ch
                            sub = len(self._subs) + 1
                            self._subs[sub] = ch["id"]
                            subs.append({"id": sub, "channelId": ch["id"]})
                        self._cond.notify_all()
                    await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": subs}))
            elif msg.type == aiohttp.WSMsgType.BINARY:
                data = msg.data
                if data[0] != 1:
                    continue
                sub, stamp = struct.unpack_from("<IQ", data, 1)
                with self._cond:
                    channel = self.channels[self._subs[sub]]
                    message = json.loads(data[13:])
                    try:
                        jsonschema.validate(message, json.loads(channel["schema"]))
                    except jsonschema.ValidationError as exc:
                        self.invalid.append(f"{channel['topic']}: {exc.message}")
                    self.messages.append((channel["topic"], stamp, message))
                    self._cond.notify_all()
