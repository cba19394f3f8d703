"""The face model: a triangle mesh in the MPEG-4 face frame, its parts, feature points and pivots.

A :class:`Face` is what the rest of the rig works on. Its vertex order is the order of the mesh
file: landmark tables and vertex groups index into it, so every loader keeps it
(``puppet.face.load.load_face``: the embedded default face, ``puppet.face.default``; a mesh file,
``puppet.face.meshfile``; a face folder, ``puppet.face.folder``).

Face frame: +x the face's own left, +y up, +z forward (out of the face); units as in the file
(the default face is in decimetres). FAPU (``Face.fapu``) make motion unit-free.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from puppet.errors import PuppetError
from puppet.fap.units import AU, FAPU_DEFINITIONS


class FaceFileError(PuppetError, ValueError):
    """A mesh file that cannot be read as a face; the message names the file and the problem."""


class MissingFeaturePointsError(PuppetError, LookupError):
    """The face lacks feature points that a computation needs; ``missing`` lists their ids."""

    def __init__(self, face_name: str, what: str, missing: list[str]) -> None:
        self.missing = list(missing)
        super().__init__(f"face {face_name!r} has no feature point(s) {', '.join(self.missing)} "
                         f"needed for {what}")


@dataclass
class Face:
    """A face mesh in the MPEG-4 face frame (+x the face's left, +y up, +z forward)."""

    name: str
    vertices: np.ndarray  # (N, 3) float64 rest positions
    triangles: np.ndarray  # (F, 3) int32
    parts: dict[str, np.ndarray]  # part name -> sorted int32 vertex indices
    feature_points: dict[str, np.ndarray] = field(default_factory=dict)  # FDP id -> xyz
    feature_vertices: dict[str, int] = field(default_factory=dict)  # FDP id -> vertex (on-vertex ones)
    pivots: dict[str, np.ndarray] = field(default_factory=dict)  # eye_l, eye_r, jaw, head; jaw_axis
    contours: dict[str, np.ndarray] = field(default_factory=dict)  # name -> closed vertex loop
    colors: np.ndarray | None = None  # (N, 3) float32 albedo in 0..1
    uv: np.ndarray | None = None  # (T, 2) float32
    triangle_uv: np.ndarray | None = None  # (F, 3) int32 rows of uv per triangle corner
    source_index: np.ndarray | None = None  # (N,) int32 vertex index in the source mesh, -1 generated
    placement: np.ndarray | None = None  # 3x4 [R | t] that took the file's coordinates into the face frame

    @property
    def fapu(self) -> dict[str, float]:
        """The face animation parameter units of this (neutral) face: IRISD0, ES0, ENS0, MNS0,
        MW0 (each a distance between feature points / 1024, in mesh units) and AU (1e-5 rad)."""
        needed = sorted({p for a, b, _ in FAPU_DEFINITIONS.values() for p in (a, b)},
                        key=_fdp_sort_key)
        missing = [p for p in needed if p not in self.feature_points]
        if missing:
            raise MissingFeaturePointsError(self.name, "FAPU", missing)
        units = {}
        for unit, (a, b, axis) in FAPU_DEFINITIONS.items():
            units[unit] = float(self.feature_points[a][axis] - self.feature_points[b][axis]) / 1024.0
        units["AU"] = AU
        return units

    @property
    def content_hash(self) -> str:
        """sha256 (hex) of the rest vertices (float64) and triangles (int32): a cache key.

        Computed on every call (about 1 ms per 50,000 vertices), never cached: the arrays can be
        edited in place, and a stale hash would key the coefficient cache on disk to another mesh."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.vertices, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(self.triangles, dtype="<i4").tobytes())
        return h.hexdigest()


@dataclass
class TexturedFace(Face):
    """A face with a texture: ``uv`` is per vertex (N, 2) (``triangle_uv`` equals the
    triangles), ``texture`` (H, W, 3) uint8 sRGB top row first, ``texture_weight`` (N,) 0-1: how
    much of the texture shows over the vertex colour (``puppet.view.renderer``)."""

    texture: np.ndarray | None = None
    texture_weight: np.ndarray | None = None
    rig_file: Path | None = None  # a face folder's face.rig, which ``rig_for_face`` takes


def _fdp_sort_key(fid: str) -> tuple[int, int]:
    group, index = fid.split(".")
    return int(group), int(index)
