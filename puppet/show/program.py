"""The program window: the face alone on a flat key colour, for OBS's window capture.

``puppet program URL`` opens a window with no cockpit that shows the face of a rig's program feed
(the ``program feed:`` URL that ``puppet live --serve`` prints) on a key colour, pure green unless
told otherwise; OBS's Window Capture with a Chroma Key filter cuts the face out of it.
``puppet live --serve ... --program`` (and ``puppet play --serve ... --program``) starts it beside
the rig (``ProgramProcess``) and closes it when the rig ends.

Decisions
---------
* **A process of its own, fed by the feed.** It connects to ``/feed`` as the page does, reads the
  face once and then each frame (``puppet.show.wire``), and draws the newest. The rig pays what one
  more viewer costs (each frame is encoded once for every viewer), its window's GL context and
  events never meet the live window's, and the same command shows a rig on another machine.
* **The desktop renderer on a key colour.** ``Renderer(backdrop=key)`` clears to the key colour
  where the studio gradient would be, and takes the feed's per-vertex materials as sent
  (``set_material_data``), so a pixel the face covers is the transparent render's pixel and every
  other pixel is exactly the key colour (antialiased edges, where the GL has them, mix the two, as
  a chroma key expects). It is drawn without the part detail: the feed does not say the parts.
* **The feed's camera**, framed for a square: a window of another shape keeps the head's height,
  as the page does. The window follows its own size.
* **Each frame drawn is echoed** to the server as the page echoes it, so the rig's delay figures
  count this window too.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import math
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlencode, urlsplit, urlunsplit

import numpy as np
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus, InvalidURI
from websockets.sync.client import ClientConnection, connect

from puppet.errors import PuppetError
from puppet.show.process import end_process
from puppet.show.wire import Quantiser, decode
from puppet.view.renderer import Camera, Renderer
from puppet.view.window import IDLE_WAKE, check_display, open_window

KEY_GREEN = (0, 255, 0)
"""The default key colour: pure green, OBS's Chroma Key default."""
TITLE = "facepuppet program"
"""The window's title: what OBS's Window Capture lists."""
SIZE = (720, 720)
"""The window's first size (the feed's own framing); it may be resized."""
REFRESH = 0.25
"""Seconds after which the window is drawn again with no new frame (a window uncovered)."""
CONNECT_TIMEOUT = 5.0


class ProgramError(PuppetError, RuntimeError):
    """The feed could not be read: a URL that is not a feed's, a refused token, a rig not there."""


def feed_url(url: str) -> str:
    """The feed's WebSocket URL of a printed ``program feed:`` URL (``http://HOST:PORT/?token=T``);
    a ``ws://HOST:PORT/feed?token=T`` URL as it is."""
    parts = urlsplit(url.strip())
    token = parse_qs(parts.query).get("token", [""])[0]
    if parts.scheme not in ("http", "ws") or not parts.netloc or not token:
        raise ProgramError(f"{url!r} is not a program feed URL: expected the one `puppet live --serve` prints, "
                           "http://HOST:PORT/?token=...")
    return urlunsplit(("ws", parts.netloc, "/feed", urlencode({"token": token}), ""))


@dataclass
class FeedFace:
    """What the feed's first message says of the face: enough to draw it as the page does."""

    n_vertices: int
    triangles: np.ndarray
    materials: np.ndarray
    camera: Camera
    quantiser: Quantiser
    texture: dict

    @classmethod
    def from_message(cls, message: dict) -> FeedFace:
        """The face of a ``face_message``; ProgramError when the message is not one."""
        try:
            n = int(message["n_vertices"])
            triangles = np.frombuffer(base64.b64decode(message["triangles"]), dtype="<u4").reshape(-1, 3)
            materials = np.frombuffer(base64.b64decode(message["materials"]), dtype="<f4").reshape(n, 4)
            view = message["camera"]
            camera = Camera(*(np.asarray(view[k], dtype=float) for k in ("eye", "target", "up")),
                            float(view["fov"]), float(view["near"]), float(view["far"]))
            quantiser = Quantiser(np.asarray(message["origin"], dtype=float), np.asarray(message["step"], dtype=float))
            texture = _texture(message, n) if message.get("textured") else {}
        except (KeyError, TypeError, ValueError) as exc:
            raise ProgramError(f"the feed's face message is not one this program reads ({type(exc).__name__}: "
                               f"{exc})") from None
        if triangles.size and int(triangles.max()) >= n:
            raise ProgramError(f"the feed's face has a triangle past its {n} vertices")
        return cls(n, triangles, materials, camera, quantiser, texture)

    def renderer(self, ctx: Any, size: tuple[int, int], key: tuple[int, int, int]) -> Renderer:
        """A renderer of this face in ``ctx`` (a window's), on the flat ``key`` colour."""
        renderer = Renderer(self.triangles, self.n_vertices, width=size[0], height=size[1], ctx=ctx,
                            backdrop=tuple(c / 255.0 for c in key), **self.texture)
        renderer.set_material_data(self.materials)
        renderer.camera = self.camera
        return renderer


def _texture(message: dict, n: int) -> dict:
    """``Renderer`` keyword arguments for a textured face message's albedo, uv and weight."""
    from PIL import Image

    image = np.asarray(Image.open(io.BytesIO(base64.b64decode(message["texture_png"]))).convert("RGB"))
    surface = np.frombuffer(base64.b64decode(message["surface"]), dtype="<f4").reshape(n, 3)
    return {"texture": image, "uv": surface[:, :2], "texture_weight": surface[:, 2]}


class FeedReader:
    """Frames of the feed back into vertices, each read in order (a DELTA adds to the frame before)."""

    def __init__(self, face: FeedFace) -> None:
        self.face = face
        self._codes: np.ndarray | None = None

    def read(self, message: bytes) -> tuple[int, float, np.ndarray]:
        """(frame number, time published, vertices (N, 3)) of one frame message."""
        _, number, published, self._codes = decode(message, self._codes)
        return number, published, self.face.quantiser.positions(self._codes)


class ProgramView:
    """The face drawn into a window's framebuffer on the key colour, at the window's size."""

    def __init__(self, face: FeedFace, window: Any, key: tuple[int, int, int] = KEY_GREEN) -> None:
        self.face, self.window, self.key = face, window, key
        self.renderer: Renderer | None = None

    def draw(self, vertices: np.ndarray) -> None:
        """Draw ``vertices`` into the window (a new renderer when the window's size changed)."""
        size = tuple(self.window.buffer_size)
        if self.renderer is None or self.renderer.size != size:
            self.release()
            self.renderer = self.face.renderer(self.window.ctx, size, self.key)
            self.window.fbo.viewport = (0, 0, *size)
        self.renderer.draw(vertices, framebuffer=self.window.fbo)

    def release(self) -> None:
        if self.renderer is not None:
            self.renderer.release()
            self.renderer = None


@contextlib.contextmanager
def open_feed(url: str) -> Iterator[tuple[ClientConnection, FeedFace]]:
    """The feed's connection and face, for a ``with`` block; ProgramError saying why not."""
    address = feed_url(url)
    where = urlsplit(address).netloc
    with contextlib.ExitStack() as stack:
        try:
            feed = stack.enter_context(connect(address, max_size=None, compression=None,
                                               open_timeout=CONNECT_TIMEOUT))
        except InvalidStatus as exc:
            raise ProgramError(f"the rig at {where} refused the feed (HTTP {exc.response.status_code}): use the "
                               "URL this run of `puppet live --serve` printed") from None
        except (OSError, TimeoutError, InvalidHandshake, InvalidURI) as exc:
            reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
            raise ProgramError(f"cannot reach the feed at {where}: {reason} (is `puppet live --serve` "
                               "running?)") from None
        yield feed, _first_face(feed, where)


def _first_face(feed: ClientConnection, where: str) -> FeedFace:
    """The face message the feed begins with."""
    try:
        first = feed.recv(timeout=CONNECT_TIMEOUT)
    except (ConnectionClosed, TimeoutError) as exc:
        raise ProgramError(f"the feed at {where} did not send the face ({type(exc).__name__})") from None
    try:
        message = json.loads(first) if isinstance(first, str) else None
    except ValueError:
        message = None
    if not isinstance(message, dict) or message.get("type") != "face":
        raise ProgramError(f"the feed at {where} did not begin with the face")
    return FeedFace.from_message(message)


class ProgramWindow:
    """The program window's loop: the newest frame of the feed drawn, until the window closes or the
    feed ends (``run`` returns which)."""

    def __init__(self, feed: ClientConnection, face: FeedFace, window: Any, key: tuple[int, int, int]) -> None:
        self.feed, self.window = feed, window
        self.frames = FeedReader(face)
        self.view = ProgramView(face, window, key)
        self.vertices: np.ndarray | None = None
        self._echo: dict | None = None
        self._drawn_at, self._drawn_size = -math.inf, None
        native = getattr(window, "_window", None) if window.name == "pyglet" else None
        self._dispatch_events = getattr(native, "dispatch_events", None)
        self._quit = False
        window.exit_key = None  # Escape is ours, so that GL objects go before the context
        window.key_event_func = self._on_key

    def run(self) -> str:
        """Draw until the window is closed (``"closed"``) or the feed ends (``"feed ended"``)."""
        try:
            while not (self._quit or self.window.is_closing):
                if not self.step(IDLE_WAKE):
                    return "feed ended"
            return "closed"
        finally:
            self.view.release()
            self.window.close()
            self.window.destroy()

    def step(self, wait: float) -> bool:
        """Read what the feed sent (waiting up to ``wait`` s for it), draw if anything changed, handle
        the window's events; False when the feed has ended."""
        try:
            fresh = self._receive(wait)
        except ConnectionClosed:
            return False
        size = tuple(self.window.buffer_size)
        stale = fresh or size != self._drawn_size or time.monotonic() - self._drawn_at > REFRESH
        if self.vertices is None or min(size) < 1 or not stale:
            self._events()
            return True
        self.view.draw(self.vertices)
        self._drawn_at, self._drawn_size = time.monotonic(), size
        self.window.swap_buffers()  # also handles the window's events
        if fresh and self._echo is not None:
            self.feed.send(json.dumps(self._echo))
        return True

    def _receive(self, wait: float) -> bool:
        """Read every frame waiting (the first up to ``wait`` s); True when one came."""
        fresh = False
        while True:
            try:
                message = self.feed.recv(timeout=0.0 if fresh else wait)
            except TimeoutError:
                return fresh
            if isinstance(message, bytes):
                number, published, self.vertices = self.frames.read(message)
                self._echo = {"drawn": number, "published": published}
                fresh = True

    def _events(self) -> None:
        if self._dispatch_events is not None:
            self._dispatch_events()
        else:
            self.window.swap_buffers()

    def _on_key(self, key: Any, action: Any, modifiers: Any) -> None:
        keys = self.window.keys
        if action == keys.ACTION_PRESS and key in (keys.Q, keys.ESCAPE):
            self._quit = True


def run_program(url: str, key: tuple[int, int, int] = KEY_GREEN, size: tuple[int, int] = SIZE) -> str:
    """``puppet program``: connect to the feed, open the window, draw until it is closed or the feed
    ends (which it returns). ``NoDisplayError``/``WindowError``/``ProgramError`` say why it cannot."""
    check_display()
    with open_feed(url) as (feed, face):
        window = open_window(TITLE, size)
        try:
            return ProgramWindow(feed, face, window, key).run()
        except KeyboardInterrupt:  # Ctrl+C in the terminal closes the window like Q
            return "closed"


class ProgramProcess:
    """``puppet program`` for a started show server, as a process of its own: one of the rig's
    outputs, so that it closes with the loop. It reads the feed by itself: ``publish`` and
    ``service`` have nothing to do."""

    def __init__(self, server: Any, key: tuple[int, int, int] = KEY_GREEN, size: tuple[int, int] = SIZE) -> None:
        host = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(server.host, server.host)
        netloc = f"[{host}]:{server.port}" if ":" in host else f"{host}:{server.port}"
        self.url = f"ws://{netloc}/feed?token={server.token}"
        self.command = [sys.executable, "-m", "puppet.cli", "program", self.url,
                        "--key-colour", "{:02X}{:02X}{:02X}".format(*key), "--size", f"{size[0]}x{size[1]}"]
        self.process = subprocess.Popen(self.command, stdin=subprocess.DEVNULL)

    def publish(self, vertices: np.ndarray, status: dict | None = None) -> None:
        """Nothing: the window reads the feed."""

    def service(self) -> None:
        """Nothing: the window sends no commands."""

    def close(self) -> None:
        """End the window's process (at once: it holds nothing to save)."""
        end_process(self.process, 5)
