"""Levels of detail for a face's inner parts: as many triangles as the screen can show.

The default face's eyeballs and teeth hold 10,876 of its 19,932 triangles, most of them behind
the lids and lips, with edges of 3-4 pixels at the live window's 640x480: on a software
rasteriser they were a quarter of the frame's drawing (0.8 of 3.1 ms, with the tongue). A part
whose mean edge, seen face-on at its distance, would be drawn shorter than ``FINE_EDGE_PX`` is drawn from a quarter of its triangles instead
(``puppet.face.decimate``: the same vertices, so the runtime's motions and normals carry over,
and colour borders such as the iris's kept). The skin, whose every vertex the DFFD moves, and
what lies on it are always drawn whole (``WHOLE_PARTS``). The choice follows the camera (its
distance and field of view, the image height) and is made again only when the camera changes;
a close-up draws every triangle.

Coarse levels are built on first use (0.3 s for the default face) and kept for the process,
keyed by the part's geometry and colours.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from puppet.face.decimate import decimate

COARSE_KEEP = 0.25
"""The share of a part's triangles its coarse level keeps (its edges about twice as long)."""

FINE_EDGE_PX = 5.0
"""A part whose mean edge, seen face-on at the part's distance, would be drawn shorter than this
many pixels is drawn coarse: at the live window's 640x480 the default face's eyeballs (2.7) and
teeth (4.1), whose coarse edges are then 4.0 and 7.8 pixels, under the skin's 9.5."""

WHOLE_PARTS = ("skin", "attached")
"""Parts always drawn with every triangle: the surface the DFFD bends, and what lies on it and
bends with it (lashes, tear lines: ``puppet.face.landmarks``'s ``attached``; a coarser copy of
the ICT head's put dark specks on its eyes)."""

_COARSE: dict[str, np.ndarray] = {}


@dataclass(frozen=True)
class _Part:
    triangles: np.ndarray  # (F, 3) int32, every triangle of the part
    used: np.ndarray  # the part's vertices (those its triangles use)
    positions: np.ndarray  # (N, 3) the whole mesh's rest positions
    colors: np.ndarray | None
    centre: np.ndarray
    edge: float  # mean edge length, mesh units


class PartDetail:
    """Which triangles to draw for a camera: the skin and any part seen close enough whole,
    the others from their coarse level."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, parts: Mapping[str, np.ndarray],
                 colors: np.ndarray | None = None) -> None:
        positions = np.asarray(vertices, dtype=np.float64)
        tri = np.asarray(triangles, dtype=np.int32).reshape(-1, 3)
        owner = np.full(len(positions), -1)
        names = [name for name in parts if name not in WHOLE_PARTS]
        for k, name in enumerate(names):
            owner[np.asarray(parts[name])] = k
        corners = owner[tri]
        own = (corners == corners[:, :1]).all(axis=1) & (corners[:, 0] >= 0)
        self.whole = tri[~own]
        self.parts: dict[str, _Part] = {}
        for k, name in enumerate(names):
            mine = tri[own & (corners[:, 0] == k)]
            if len(mine):
                self.parts[name] = _part(positions, mine, colors)

    def levels(self, eye: np.ndarray, back: np.ndarray, fov: float, height: int) -> dict[str, str]:
        """Per part, ``"coarse"`` or ``"fine"`` as seen by a camera at ``eye`` looking along
        ``-back`` (unit), ``fov`` degrees tall over ``height`` pixels."""
        focal = height / (2.0 * np.tan(np.radians(fov) / 2.0))
        levels = {}
        for name, part in self.parts.items():
            depth = float(np.dot(np.asarray(eye) - part.centre, back))
            seen_small = depth > 0 and part.edge * focal / depth < FINE_EDGE_PX
            levels[name] = "coarse" if seen_small else "fine"
        return levels

    def triangles(self, levels: Mapping[str, str]) -> np.ndarray:
        """The triangles to draw (int32, (M, 3)) at ``levels`` (``levels``'s result)."""
        chosen = [_coarse(part) if levels.get(name) == "coarse" else part.triangles
                  for name, part in self.parts.items()]
        return np.concatenate([self.whole, *chosen]).astype(np.int32)


def _part(positions: np.ndarray, triangles: np.ndarray, colors: np.ndarray | None) -> _Part:
    used = np.unique(triangles)
    edges = positions[triangles[:, [1, 2, 0]]] - positions[triangles]
    return _Part(triangles, used, positions, None if colors is None else np.asarray(colors),
                 positions[used].mean(axis=0), float(np.linalg.norm(edges, axis=2).mean()))


def _coarse(part: _Part) -> np.ndarray:
    """The part's coarse level, built once per process for the same geometry and colours."""
    digest = hashlib.sha256(np.ascontiguousarray(part.triangles, dtype="<i4").tobytes())
    digest.update(np.ascontiguousarray(part.positions[part.used], dtype="<f8").tobytes())
    if part.colors is not None:
        digest.update(np.ascontiguousarray(part.colors[part.used], dtype="<f4").tobytes())
    key = digest.hexdigest()
    if key not in _COARSE:
        _COARSE[key] = decimate(part.positions, part.triangles, COARSE_KEEP, colors=part.colors)
    return _COARSE[key]
