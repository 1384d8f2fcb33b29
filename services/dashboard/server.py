"""The dashboard's web server: one page, its assets, and a Server-Sent Events stream (docs/semantics.md §7).

aiohttp serves ``static/`` (the page, its script and style sheet, all written
here: no CDN, works offline) and:

- ``GET /events``: ``text/event-stream``; a ``snapshot`` message first, then every
  :class:`~services.dashboard.board.Board` update as it happens.  Browsers'
  ``EventSource`` reconnects by itself (``retry: 1000``) and gets a fresh snapshot.
- ``GET /api/snapshot``: the snapshot as JSON.
- ``GET /api/check?command=skillset:transition``: the monitor's command check, as JSON.
- ``POST /api/goal``: the goal box (docs/semantics.md §8): a JSON form (``op``, ``goals``, ``inputs``,
  ``mode``, ``replace``; :mod:`~services.dashboard.goalbox`) sent to the pilot under the
  dashboard's login; answers ``{"ok": true, "reply": PilotGoalReply}``, or ``{"ok": false,
  "error", "field", "line", "column"}`` for a goal that cannot be sent or was rejected (its
  place in the form), or that no pilot answered.

The server runs its asyncio loop in a thread of its own, so it can sit beside
the embedded monitor of ``skinet run``; updates cross from Zenoh's threads with
``call_soon_threadsafe``, and only while a page is open: with none, the observer's
call costs one test.  Each batch of updates is encoded once (JSON, in Rust:
``pydantic_core.to_json``) for every page.  A client too slow to keep up is
dropped (it reconnects and starts from a snapshot).
"""

from __future__ import annotations

import asyncio
import errno
import threading
from pathlib import Path
from typing import Any

from aiohttp import web
from pydantic_core import to_json

from services.common.goals import GOAL_TIMEOUT, NoPilot
from services.dashboard.board import Update
from services.dashboard.goalbox import GoalFormError, goal_lines, goal_request, place
from services.dashboard.observer import Observer
from skinet.errors import SkinetError

STATIC = Path(__file__).parent / "static"
ASSETS = {"app.js": "text/javascript", "style.css": "text/css"}
QUEUE_LIMIT = 10_000  # pending updates per client before it is dropped
KEEPALIVE = 15.0  # seconds between comment lines on an idle stream


class PortError(SkinetError):
    """The dashboard cannot listen where it was asked to."""


def _frame(update: Update) -> bytes:
    return b"data: " + to_json(update) + b"\n\n"


class Dashboard:
    """The web server of one observer; :meth:`start` returns once it listens."""

    def __init__(self, observer: Observer, host: str = "127.0.0.1", port: int = 8080):
        self.observer, self.host, self.port = observer, host, port
        self._loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self._clients: set[asyncio.Queue[bytes | None]] = set()  # each open page's frames to send
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    def start(self) -> None:
        """Listen on host:port; raises :class:`PortError` (port in use, bad address)."""
        ready: dict[str, Any] = {}
        started = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(ready, started), name="skinet-dashboard", daemon=True)
        self._thread.start()
        started.wait()
        if "error" in ready:
            self._thread.join()
            raise PortError(ready["error"])

    def close(self) -> None:
        loop = self._loop
        if loop is None or self._thread is None:
            return
        asyncio.run_coroutine_threadsafe(self._stop(), loop).result(timeout=10)
        loop.call_soon_threadsafe(loop.stop)
        self._thread.join(timeout=10)
        self._loop = None

    # -- server thread ------------------------------------------------------------------

    def _run(self, ready: dict[str, Any], started: threading.Event) -> None:
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._start())
        except OSError as exc:
            ready["error"] = _bind_error(self.host, self.port, exc)
        if "error" in ready:
            started.set()
            loop.close()
            return
        self._loop = loop
        self.observer.listen(self._post_threadsafe)
        started.set()
        loop.run_forever()
        loop.close()

    async def _start(self) -> None:
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{name}", self._asset)
        app.router.add_get("/events", self._events)
        app.router.add_get("/api/snapshot", self._snapshot)
        app.router.add_get("/api/check", self._check)
        app.router.add_post("/api/goal", self._goal)
        self._runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=1.0)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port, reuse_address=True)
        try:
            await site.start()
        except OSError:
            await self._runner.cleanup()
            raise
        if self.port == 0:  # an ephemeral port: report the one chosen
            self.port = site._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]

    async def _stop(self) -> None:
        self.observer.unlisten(self._post_threadsafe)
        for queue in list(self._clients):
            queue.put_nowait(None)
        if self._runner is not None:
            await self._runner.cleanup()

    def _post_threadsafe(self, updates: list[Update]) -> None:
        loop = self._loop
        # No page open: nothing to do (a page registers before it takes its snapshot, see _events).
        if self._clients and loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._post, updates)

    def _post(self, updates: list[Update]) -> None:
        if not self._clients:
            return
        data = b"".join(_frame(u) for u in updates)
        for queue in list(self._clients):
            if queue.qsize() >= QUEUE_LIMIT:
                self._clients.discard(queue)
                queue.put_nowait(None)  # too slow: drop it, it reconnects to a snapshot
            else:
                queue.put_nowait(data)

    # -- handlers -----------------------------------------------------------------------

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    async def _asset(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        if name not in ASSETS:
            raise web.HTTPNotFound()
        return web.FileResponse(STATIC / name, headers={"Content-Type": ASSETS[name], "Cache-Control": "no-cache"})

    async def _snapshot(self, request: web.Request) -> web.Response:
        return web.json_response(self.observer.snapshot())

    async def _check(self, request: web.Request) -> web.Response:
        command = request.query.get("command", "")
        try:
            reply = await asyncio.get_running_loop().run_in_executor(None, self.observer.check, command)
        except (ValueError, LookupError) as exc:
            return web.json_response({"ok": False, "error": str(exc)}, status=400 if isinstance(exc, ValueError) else 504)
        return web.json_response(reply.model_dump(mode="json"))

    async def _goal(self, request: web.Request) -> web.Response:
        try:
            form = await request.json()
        except ValueError:
            form = None
        if not isinstance(form, dict):
            return web.json_response({"ok": False, "error": "expected a JSON object"}, status=400)
        loop = asyncio.get_running_loop()
        try:
            model = await loop.run_in_executor(None, self.observer.model)
            goal = goal_request(self.observer.name, form, model)
            reply = await loop.run_in_executor(None, self.observer.goal, goal, GOAL_TIMEOUT)
        except GoalFormError as exc:
            return web.json_response({"ok": False, **exc.placed.json()})
        except NoPilot as exc:
            return web.json_response({"ok": False, "error": str(exc), "field": None}, status=504)
        except SkinetError as exc:
            return web.json_response({"ok": False, "error": str(exc), "field": None}, status=502)
        if not reply.accepted:
            lines = [n for n, _ in goal_lines(str(form.get("goals", "")))]
            return web.json_response({"ok": False, **place(reply.reason, lines).json(), "rejected": True})
        return web.json_response({"ok": True, "reply": reply.model_dump(mode="json")})

    async def _events(self, request: web.Request) -> web.StreamResponse:
        response = web.StreamResponse(headers={
            "Content-Type": "text/event-stream", "Cache-Control": "no-cache", "X-Accel-Buffering": "no"})
        await response.prepare(request)
        queue: asyncio.Queue[bytes | None] = asyncio.Queue()
        # Registered before the snapshot: an update the observer posts once it is registered comes after the snapshot
        # (or is in it: applying it again is harmless); one posted before is in the snapshot.
        self._clients.add(queue)
        try:
            snapshot = self.observer.snapshot()
            await response.write(b"retry: 1000\n\n" + _frame(snapshot))
            while True:
                try:
                    data = await asyncio.wait_for(queue.get(), KEEPALIVE)
                except asyncio.TimeoutError:
                    await response.write(b": keepalive\n\n")
                    continue
                if data is None:
                    break
                await response.write(data)
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        finally:
            self._clients.discard(queue)
        return response


def _bind_error(host: str, port: int, exc: OSError) -> str:
    if exc.errno == errno.EADDRINUSE:
        return f"cannot listen on {host}:{port}: the port is in use (choose another port)"
    return f"cannot listen on {host}:{port}: {exc.strerror or exc}"
