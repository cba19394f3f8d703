"""The show server: a page with the face for OBS or a browser, its feed, and the control API.

``ShowServer(face, host, port)`` serves, on one port, with a token printed at start:

* ``/?token=T``: the page (``page/``), the face alone on a transparent background (the page and
  its script are served to anyone: they hold nothing, and read the token from the page's URL);
* ``/feed?token=T``: a WebSocket that sends the face once, then every frame (``puppet.show.wire``),
  and reads back the page's echo of each frame it drew, to time the delay;
* ``/api?token=T``: the WebSocket JSON control API (``puppet.show.api``);

and, when asked (``osc``), OSC control addresses on a UDP port (``puppet.show.osccontrol``).

A socket opened without the token is refused (HTTP 403), as is one from a page of another origin.

It runs in a thread of its own with its own asyncio loop, and the live loop never waits for it:
``publish`` copies the frame's vertices into a slot and wakes the server, which encodes the newest
frame once and sends it to each viewer that is ready (a slow viewer skips frames, it never queues
them); ``service`` runs the API's queued commands between frames. Everything a client sends is
bounded (``api.MAX_MESSAGE``) and checked; a client that goes away mid-message changes nothing.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import dataclasses
import hmac
import http
import json
import queue
import secrets
import threading
import time
from collections import deque
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np
from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from puppet.errors import PuppetError
from puppet.show import api
from puppet.show.osccontrol import OscControl
from puppet.show.stage import Stage
from puppet.show.wire import FrameEncoder, Quantiser, face_message
from puppet.view.renderer import Camera

PAGES = {"/": ("index.html", "text/html; charset=utf-8"), "/index.html": ("index.html", "text/html; charset=utf-8"),
         "/face.js": ("face.js", "text/javascript; charset=utf-8")}
SOCKETS = ("/feed", "/api")
COMMAND_TIMEOUT = 2.0
"""Seconds a queued command may wait for the live loop before its client is told so."""
DELAYS = 600
"""How many of the newest frame delays are kept (``delays_ms``)."""
FEED_FPS = 60
"""The most frames a second the feed sends, however fast the loop runs (a display shows no more)."""
API_RATE, API_BURST = 200.0, 50
"""Messages a second one API client is answered at, after a burst of ``API_BURST``: a client
sending faster waits (its socket fills, TCP slows it), so no client can take the live loop's CPU."""


class ShowError(PuppetError, RuntimeError):
    """The server could not start (the port is taken, the address is not this machine's)."""


class ShowServer:
    """The page, feed and control API of one face; ``start()``, then ``publish`` every frame."""

    def __init__(self, face: Any, camera: Camera, *, host: str = "127.0.0.1", port: int = 8765,
                 size: tuple[int, int] = (640, 640), stage: Stage | None = None, token: str | None = None,
                 osc: tuple[str, int] | None = None) -> None:
        self.host, self.port = host, port
        self.osc_address = osc
        self.osc: OscControl | None = None
        self.token = token or secrets.token_urlsafe(16)
        self.stage = stage or Stage()
        quantiser = Quantiser.around(np.asarray(face.vertices, dtype=float))
        self._face_text = json.dumps(face_message(face, camera, quantiser, size))
        self._encoder = FrameEncoder(quantiser)
        self._slot: tuple[np.ndarray, float] | None = None
        self._slot_lock = threading.Lock()
        self._commands: queue.SimpleQueue = queue.SimpleQueue()
        self.status: dict = {"type": "status"}
        self.delays_ms: deque[float] = deque(maxlen=DELAYS)
        self.viewers = 0
        self.counts = {"messages": 0, "refused": 0, "feed_bytes": 0, "frames_sent": 0}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._frame = None  # asyncio.Event of the next frame, replaced when it comes
        self._pending, self._taken_at = False, -1.0
        self._stopped = None
        self._thread: threading.Thread | None = None

    # -- what the live loop calls -------------------------------------------------------------

    @property
    def page_url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={self.token}"

    def start(self) -> ShowServer:
        """Bind and serve in a thread; ShowError naming the address when it cannot bind."""
        started: concurrent.futures.Future = concurrent.futures.Future()
        self._thread = threading.Thread(target=self._run, args=(started,), name="show server", daemon=True)
        self._thread.start()
        error = started.result(timeout=10)
        if error is not None:
            self._thread.join(2)
            raise ShowError(f"cannot serve on {self.host}:{self.port}: {error}")
        return self

    def publish(self, vertices: np.ndarray, status: dict | None = None) -> None:
        """A new frame (and the rig's status): copied, and the server woken; never blocks on it."""
        if self._loop is None:
            return
        frame = (np.array(vertices, dtype=float), time.monotonic())
        with self._slot_lock:
            self._slot = frame
        if status is not None:
            self.status = {"type": "status", **status}
        self._loop.call_soon_threadsafe(self._frame_due)

    def service(self) -> None:
        """Run the API commands waiting for the live loop (call between frames, on its thread)."""
        while True:
            try:
                message, future = self._commands.get_nowait()
            except queue.Empty:
                return
            if future.done():  # its client gave up waiting
                continue
            try:
                future.set_result(self.stage.run(message))
            except api.ApiError as exc:
                future.set_exception(exc)
            except Exception as exc:  # noqa: BLE001 -- a command's failure is its client's answer, not the loop's
                future.set_exception(api.ApiError(f"{message['type']}: {type(exc).__name__}: {exc}"))

    def thread_cpu(self) -> float:
        """The CPU seconds the server's thread has used so far (for what it costs a machine)."""
        future = concurrent.futures.Future()
        self._loop.call_soon_threadsafe(lambda: future.set_result(time.thread_time()))
        return future.result(timeout=5)

    def close(self) -> None:
        if self._loop is not None and self._stopped is not None:
            self._loop.call_soon_threadsafe(self._stopped.set)
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None
        self._loop = None

    def __enter__(self) -> ShowServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the server's thread ------------------------------------------------------------------

    def _run(self, started: concurrent.futures.Future) -> None:
        asyncio.run(self._serve(started))

    async def _serve(self, started: concurrent.futures.Future) -> None:
        self._stopped = asyncio.Event()
        self._frame = asyncio.Event()
        try:
            server = await serve(self._connection, self.host, self.port, process_request=self._http,
                                 compression=None, max_size=api.MAX_MESSAGE, max_queue=4, write_limit=2**20)
        except OSError as exc:
            started.set_result(exc.strerror or str(exc))
            return
        self.port = server.sockets[0].getsockname()[1]
        self._loop = asyncio.get_running_loop()
        if self.osc_address is not None:
            try:
                transport, self.osc = await self._loop.create_datagram_endpoint(
                    lambda: OscControl(self.answer), local_addr=self.osc_address)
            except OSError as exc:
                server.close()
                started.set_result(f"OSC control on {self.osc_address[0]}:{self.osc_address[1]}: "
                                   f"{exc.strerror or exc}")
                return
            self.osc_address = transport.get_extra_info("sockname")[:2]
        started.set_result(None)
        async with server:
            await self._stopped.wait()
            server.close()

    def _frame_due(self) -> None:
        """Take the newest frame now, or when ``FEED_FPS`` allows (once, however many come)."""
        if self._pending:
            return
        wait = self._taken_at + 1.0 / FEED_FPS - time.monotonic()
        if wait > 0:
            self._pending = True
            self._loop.call_later(wait, self._take_frame)
        else:
            self._take_frame()

    def _take_frame(self) -> None:
        """Encode the newest frame for the viewers; with none, leave it for the first to come."""
        self._pending = False
        if not self.viewers:
            return
        self._taken_at = time.monotonic()
        with self._slot_lock:
            slot, self._slot = self._slot, None
        if slot is None:
            return
        self._encoder.publish(*slot)
        event, self._frame = self._frame, asyncio.Event()
        event.set()

    def _http(self, connection: ServerConnection, request: Request) -> Response | None:
        url = urlsplit(request.path)
        token = parse_qs(url.query).get("token", [""])[0]
        if url.path not in PAGES and url.path not in SOCKETS:
            return connection.respond(http.HTTPStatus.NOT_FOUND, f"no {url.path} here: the page is /?token=...\n")
        if url.path in PAGES:  # the page's own code holds nothing; it reads the token from its URL
            return _page(connection, *PAGES[url.path])
        if not hmac.compare_digest(token.encode(), self.token.encode()):
            return connection.respond(http.HTTPStatus.FORBIDDEN, "missing or wrong token: use the URL "
                                      "`puppet live --serve` printed\n")
        origin = request.headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc != request.headers.get("Host"):
            return connection.respond(http.HTTPStatus.FORBIDDEN, "another origin's page may not connect\n")
        return None

    async def _connection(self, ws: ServerConnection) -> None:
        path = urlsplit(ws.request.path).path
        with contextlib.suppress(ConnectionClosed):
            if path == "/feed":
                await self._feed(ws)
            else:
                await self._api(ws)

    async def _feed(self, ws: ServerConnection) -> None:
        self.viewers += 1
        self._take_frame()  # the frame waiting since the last viewer left, if any
        echoes = asyncio.create_task(self._echoes(ws))
        try:
            await ws.send(self._face_text)
            sent = -1
            while True:
                if self._encoder.number == sent or self._encoder.number == 0:
                    if await self._next_frame_or_gone(echoes):
                        return
                    continue
                message = self._encoder.message(sent)
                sent = self._encoder.number
                await ws.send(message)
                self.counts["feed_bytes"] += len(message)
                self.counts["frames_sent"] += 1
        finally:
            self.viewers -= 1
            echoes.cancel()

    async def _next_frame_or_gone(self, echoes: asyncio.Task) -> bool:
        """Wait for the next frame, or for the viewer to go (True): a viewer that left while no frame
        came (a paused take) is let go at once, not at the next frame."""
        frame = asyncio.ensure_future(self._frame.wait())
        try:
            await asyncio.wait((frame, echoes), return_when=asyncio.FIRST_COMPLETED)
        finally:
            frame.cancel()
        return echoes.done()

    async def _echoes(self, ws: ServerConnection) -> None:
        """The page's echo of each frame drawn: ``{"drawn": number, "published": t}``; returns when
        the viewer's connection closes."""
        with contextlib.suppress(ConnectionClosed):
            async for text in ws:
                with contextlib.suppress(ValueError, TypeError, KeyError):
                    self.delays_ms.append((time.monotonic() - float(json.loads(text)["published"])) * 1e3)

    async def _api(self, ws: ServerConnection) -> None:
        subscription: asyncio.Task | None = None
        bucket = TokenBucket(API_RATE, API_BURST)
        try:
            async for text in ws:
                await asyncio.sleep(bucket.wait())
                self.counts["messages"] += 1
                reply, interval = await self._answer(text)
                if interval is not None:
                    if subscription is not None:
                        subscription.cancel()
                    subscription = asyncio.create_task(self._events(ws, interval)) if interval else None
                await ws.send(json.dumps(reply))
        finally:
            if subscription is not None:
                subscription.cancel()

    async def _answer(self, text: str | bytes) -> tuple[dict, float | None]:
        """The reply to one message, and a subscription's new interval (0: none; None: as it was)."""
        try:
            message = api.parse(text)
        except api.ApiError as exc:
            self.counts["refused"] += 1
            return {"id": None, "ok": False, "error": str(exc)}, None
        return await self.answer(message)

    async def answer(self, message: dict) -> tuple[dict, float | None]:
        """The reply to one checked message (``api.check``), from the WebSocket API or OSC."""
        ident, kind, interval = message.get("id"), message["type"], None
        try:
            if kind == "status":
                body = self._status()
            elif kind == "subscribe":
                body, interval = {}, float(message.get("interval", 0.5))
            elif kind == "unsubscribe":
                body, interval = {}, 0.0
            elif kind == "set":
                body = self.stage.set(message["channels"], message.get("device"))
            else:
                body = await self._on_loop(message)
        except api.ApiError as exc:
            self.counts["refused"] += 1
            return {"id": ident, "ok": False, "error": str(exc)}, None
        return {"id": ident, "ok": True, **body}, interval

    async def _on_loop(self, message: dict) -> dict:
        if not self.stage.live:
            return self.stage.run(message)
        future: concurrent.futures.Future = concurrent.futures.Future()
        self._commands.put((message, future))
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), COMMAND_TIMEOUT)
        except TimeoutError:
            future.cancel()
            raise api.ApiError(f"{message['type']}: the live loop did not answer within {COMMAND_TIMEOUT} s") from None

    def _status(self) -> dict:
        status = dict(self.status)
        status.pop("type", None)
        return {"status": status, "viewers": self.viewers}

    async def _events(self, ws: ServerConnection, interval: float) -> None:
        recording = self.status.get("recording")
        next_at = 0.0
        with contextlib.suppress(ConnectionClosed):
            while True:
                now = time.monotonic()
                changed = self.status.get("recording") != recording
                if changed or now >= next_at:
                    recording = self.status.get("recording")
                    await ws.send(json.dumps({"type": "status", **self._status()}))
                    next_at = now + interval
                await asyncio.sleep(min(interval, 0.05))


class TokenBucket:
    """``rate`` a second after a burst of ``burst``: ``wait()`` says how long to wait for the next."""

    def __init__(self, rate: float, burst: int) -> None:
        self.rate, self.burst = rate, burst
        self._tokens, self._at = float(burst), time.monotonic()

    def wait(self) -> float:
        now = time.monotonic()
        self._tokens = min(self.burst, self._tokens + (now - self._at) * self.rate) - 1.0
        self._at = now
        return max(0.0, -self._tokens / self.rate)


def _page(connection: ServerConnection, name: str, kind: str) -> Response:
    """One of the page's files, as an HTTP response."""
    body = resources.files("puppet.show").joinpath("page", name).read_bytes()
    response = connection.respond(http.HTTPStatus.OK, "")
    for header in ("Content-Type", "Content-Length"):
        del response.headers[header]
    response.headers["Content-Type"] = kind
    response.headers["Content-Length"] = str(len(body))
    response.headers["Cache-Control"] = "no-store"
    return dataclasses.replace(response, body=body)
