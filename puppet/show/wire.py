"""What the program feed sends: the face once, then each frame's vertices, small.

A page that shows the face needs its topology, materials, camera and lights once (``face_message``,
JSON) and then, per frame, only where the vertices are. Positions are quantised to ``BITS`` bits
per coordinate over the rest pose's box widened by ``MARGIN`` on every side, and laid out a
coordinate at a time (every x, then every y, then every z: neighbours' codes are alike, so they
deflate better). A frame is sent as its difference from the frame before (``DELTA``; modulo
2^16, so no difference overflows), then deflated (zlib level 1). A client that missed a frame,
or has just connected, gets the whole frame instead (``KEY``). The page inflates it
(``DecompressionStream``), adds, and draws.

A frame message: kind (u8: ``KEY`` or ``DELTA``), three zero bytes, the frame number (u32) and the
time it was published (f64, seconds on the server's monotonic clock: the page echoes it back so
the server can time the delay), all little-endian, then the deflated u16 array (3 x N).

Measured on the demo take (``puppet bench --only show``): 14 bits and this layout send 40% less
than 16 bits interleaved (0.40 against 0.67 MB/s at 30 fps), for 0.7 ms of CPU a frame; deflate
level 6 would save another 18% for 7 times the CPU.
"""

from __future__ import annotations

import base64
import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from puppet.view.renderer import (
    LIGHT_UNIFORMS,
    SHADING_MODES,
    Camera,
    camera_uniforms,
    material_data,
    webgl_shaders,
)

KEY, DELTA = 1, 2
HEADER = struct.Struct("<B3xId")
BITS = 14
"""Bits per coordinate: a step of 1/16383 of twice the head's size, a fifth of a pixel with the
head filling a 4K frame's height."""
MARGIN = 0.5
"""How far past the rest pose's box (in box sizes, each side) a vertex may move and still be sent
exactly; one beyond is sent at the box's edge."""
TOP = 2**BITS - 1
LEVEL = 1
"""zlib's compression level for frames: the fastest; the deltas are mostly zeros."""


def _b64(array: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")


@dataclass
class Quantiser:
    """Positions <-> u16 codes over a box around the rest pose."""

    origin: np.ndarray
    step: np.ndarray

    @classmethod
    def around(cls, rest: np.ndarray) -> Quantiser:
        low, high = rest.min(axis=0), rest.max(axis=0)
        size = np.maximum(high - low, 1e-6)
        origin = low - MARGIN * size
        return cls(origin, size * (1.0 + 2.0 * MARGIN) / TOP)

    def codes(self, vertices: np.ndarray) -> np.ndarray:
        """(3, N) u16 codes: every x, then every y, then every z (one temporary, worked in
        place: this runs for every frame a viewer is sent)."""
        scaled = np.subtract(vertices, self.origin)
        scaled /= self.step
        np.rint(scaled, out=scaled)
        np.clip(scaled, 0, TOP, out=scaled)
        return scaled.T.astype("<u2", order="C")

    def positions(self, codes: np.ndarray) -> np.ndarray:
        """(N, 3) positions of (3, N) codes."""
        return self.origin + codes.T.astype(float) * self.step


def face_message(face, camera: Camera, quantiser: Quantiser, size: tuple[int, int]) -> dict:
    """The page's first message: topology, materials, shaders, camera and lights (JSON-able)."""
    textured = getattr(face, "texture", None) is not None
    message = {
        "type": "face", "n_vertices": len(face.vertices), "width": size[0], "height": size[1],
        "triangles": _b64(np.asarray(face.triangles, dtype="<u4")),
        "materials": _b64(material_data(len(face.vertices), face.colors, None).astype("<f4")),
        "origin": quantiser.origin.tolist(), "step": quantiser.step.tolist(),
        "camera": {"eye": camera.eye.tolist(), "target": camera.target.tolist(), "up": camera.up.tolist(),
                   "fov": camera.fov, "near": camera.near, "far": camera.far},
        "uniforms": {name: np.asarray(value, dtype=float).ravel().tolist() for name, value in LIGHT_UNIFORMS.items()},
        "light_direction": camera_uniforms(camera, size[0] / size[1])["light_direction"].ravel().tolist(),
        "shaders": {shading: webgl_shaders(textured, shading) for shading in SHADING_MODES}, "textured": textured,
    }
    if textured:
        message.update(texture_message(face))
    return message


def texture_message(face) -> dict:
    """A textured face's albedo as PNG, and its per-vertex uv and texture weight."""
    import io

    from PIL import Image

    png = io.BytesIO()
    Image.fromarray(np.asarray(face.texture, dtype=np.uint8)[..., :3]).save(png, format="PNG")
    weight = getattr(face, "texture_weight", None)
    surface = np.empty((len(face.vertices), 3), dtype="<f4")
    surface[:, :2] = face.uv
    surface[:, 2] = 1.0 if weight is None else np.clip(weight, 0.0, 1.0)
    return {"texture_png": base64.b64encode(png.getvalue()).decode("ascii"), "surface": _b64(surface)}


@dataclass
class FrameEncoder:
    """Each published frame as a KEY message and, when the frame before was published just
    before it, a DELTA message; each made once however many clients are sent it."""

    quantiser: Quantiser
    number: int = 0
    time: float = 0.0
    _codes: np.ndarray | None = None
    _previous: np.ndarray | None = None
    _made: dict[int, bytes] = field(default_factory=dict)

    def publish(self, vertices: np.ndarray, time: float) -> int:
        """Take a new frame (its vertices are copied, as codes); returns its number."""
        self._previous, self._codes = self._codes, self.quantiser.codes(vertices)
        self.number += 1
        self.time = time
        self._made = {}
        return self.number

    def message(self, after: int) -> bytes:
        """The newest frame, for a client whose last frame was number ``after``."""
        kind = DELTA if after == self.number - 1 and self._previous is not None else KEY
        made = self._made.get(kind)
        if made is None:
            codes = self._codes if kind == KEY else self._codes - self._previous  # u16: modulo 2^16
            made = HEADER.pack(kind, self.number, self.time) + zlib.compress(codes.tobytes(), LEVEL)
            self._made[kind] = made
        return made


def decode(message: bytes, previous: np.ndarray | None) -> tuple[int, int, float, np.ndarray]:
    """A frame message read back as the page reads it: (kind, number, time, u16 codes (3, N));
    ``previous`` are the codes of the frame before, needed for a DELTA."""
    kind, number, published = HEADER.unpack_from(message)
    codes = np.frombuffer(zlib.decompress(message[HEADER.size:]), dtype="<u2").reshape(3, -1)
    if kind == DELTA:
        codes = previous + codes
    return kind, number, published, codes
