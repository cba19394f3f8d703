"""The face over NDI with alpha: ``puppet live --ndi NAME`` (and ``puppet play --ndi NAME``).

An ``NdiOutput`` is one of the rig's outputs (``puppet.view.liveoutput``): each frame's vertices
are drawn by the transparent renderer (``Renderer(transparent=True)``) and sent as an NDI source
named ``NAME``, RGBA with the face's alpha, which OBS receives through the DistroAV plugin, and
vMix, Resolume or another machine's NDI tools as they are.

Decisions
---------
* **A thread of its own.** Drawing a frame offscreen and reading it back costs a software
  rasteriser tens of milliseconds, which the live loop must not wait for: ``publish`` only puts
  the newest vertices in a slot and wakes the thread; a frame the thread had no time for is
  skipped, never queued. The renderer and its standalone GL context are made on that thread.
* **Straight alpha.** NDI's RGBA is not premultiplied; the renderer's edge pixels, where a GPU
  antialiases them, are (the backdrop is transparent black), so their colour is divided by their
  alpha before sending. A software rasteriser draws no partial pixels, and nothing changes there.
* **Through the ``ndi`` extra** (``pip install ".[ndi]"``: ``cyndilib``, which carries
  the NDI runtime under NDI's own licence); without it, ``--ndi`` says how to get it.
* **Discovery** is NDI's own (mDNS). Where it does not reach (containers, some VMs), NDI's
  Access Manager, or its config file ``ndi-config.v1.json`` in ``$NDI_CONFIG_DIR`` or ``~/.ndi/``,
  lists the sender's address under ``networks.ips``.
"""

from __future__ import annotations

import sys
import threading
import warnings
from fractions import Fraction
from typing import Any

import numpy as np

from puppet.errors import PuppetError
from puppet.view.renderer import Camera, Renderer, aim_camera
from puppet.view.rendertake import head_points

SIZE = (720, 720)
"""The frames' size: the program feed's (``puppet.show.serving.FEED_SIZE``)."""
FPS = Fraction(30)
"""The frame rate the source announces; frames are sent as the rig publishes them."""


class NdiError(PuppetError, RuntimeError):
    """NDI cannot be used here: the extra is not installed, or the sender did not open."""


def straight_alpha(rgba: np.ndarray) -> np.ndarray:
    """An RGBA image (H, W, 4) uint8 whose colour is premultiplied by its alpha, with the colour of
    every partly covered pixel divided by it (in place; returned)."""
    alpha = rgba[..., 3]
    partial = (alpha > 0) & (alpha < 255)
    if partial.any():
        share = alpha[partial].astype(np.float32)[:, None] / 255.0
        rgba[partial, :3] = np.clip(np.rint(rgba[partial, :3] / share), 0, 255).astype(np.uint8)
    return rgba


def load_cyndilib() -> Any:
    """cyndilib's sender, video frame and structs modules; NdiError saying how to get them."""
    try:
        from cyndilib import sender, video_frame
        from cyndilib.wrapper import ndi_structs
    except ImportError as exc:
        raise NdiError(f"--ndi needs cyndilib, the ndi extra: pip install \".[ndi]\" in facepuppet's folder, "
                       f"or pip install cyndilib ({exc})") from None
    return sender, video_frame, ndi_structs


class NdiOutput:
    """The face as an NDI source named ``name``, ``size`` pixels, from ``camera``; ``publish`` every
    frame, ``close`` at the end."""

    def __init__(self, face: Any, camera: Camera, name: str, size: tuple[int, int] = SIZE) -> None:
        sender, video_frame, ndi_structs = load_cyndilib()
        self.face, self.camera, self.name, self.size = face, camera, name, size
        frame = video_frame.VideoSendFrame()
        frame.set_resolution(*size)
        frame.set_frame_rate(FPS)
        frame.set_fourcc(ndi_structs.FourCC.RGBA)
        self.sender = sender.Sender(name, clock_video=True)
        self.sender.set_video_frame(frame)
        try:
            self.sender.open()
        except Exception as exc:  # noqa: BLE001 -- cyndilib's failure to open, whatever it raises
            raise NdiError(f"NDI source {name!r} did not open: {exc}") from None
        self.sent = 0
        self._slot: np.ndarray | None = None
        self._wake = threading.Condition()
        self._closing = False
        self._failed: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="NDI sender", daemon=True)
        self._thread.start()

    @property
    def source_name(self) -> str:
        """The name receivers list it under: ``MACHINE (name)``."""
        return self.sender.source.name if self.sender.source is not None else self.name

    def publish(self, vertices: np.ndarray, status: dict | None = None) -> None:
        """The newest frame: copied, and the sender woken; never waits for the drawing."""
        with self._wake:
            self._slot = np.array(vertices, dtype=np.float32)
            self._wake.notify()

    def service(self) -> None:
        """Nothing to run on the loop's thread; a sender that failed says so here, once, as a
        warning: the rig goes on without it."""
        failed, self._failed = self._failed, None
        if failed is not None:
            warnings.warn(f"NDI source {self.name!r} stopped: {type(failed).__name__}: {failed}", RuntimeWarning,
                          stacklevel=2)

    def close(self) -> None:
        with self._wake:
            self._closing = True
            self._wake.notify()
        self._thread.join(10)
        self.sender.close()

    def _run(self) -> None:
        try:
            renderer = Renderer.for_face(self.face, width=self.size[0], height=self.size[1], transparent=True)
        except BaseException as exc:  # noqa: BLE001 -- reported on the loop's thread by service()
            self._failed = exc
            return
        renderer.camera = self.camera
        try:
            while True:
                with self._wake:
                    while self._slot is None and not self._closing:
                        self._wake.wait()
                    if self._closing:
                        return
                    vertices, self._slot = self._slot, None
                image = straight_alpha(renderer.render(vertices))
                self.sender.write_video(image.reshape(-1))
                self.sent += 1
        except BaseException as exc:  # noqa: BLE001 -- reported on the loop's thread by service()
            self._failed = exc
        finally:
            renderer.release()


def ndi_output(face: Any, name: str, view: str = "front", size: tuple[int, int] = SIZE) -> NdiOutput:
    """The NDI source of a rig's face, framed on the head from ``view`` as the program feed is; its
    name, as receivers list it, said on stderr."""
    output = NdiOutput(face, aim_camera(head_points(face), size, view), name, size)
    print(f"NDI source: {output.source_name}  (OBS: an NDI Source, with the DistroAV plugin)", file=sys.stderr)
    return output
