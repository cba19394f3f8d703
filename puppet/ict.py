"""The ICT-FaceKit head (read from ``../shared/assets``, never copied) with a rig for benchmarks.

The ICT head has 68 iBUG landmark vertices but no MPEG-4 feature points yet (converting them is
the auto-rig's job), so this rig is the plain one those landmarks allow: one DFFD region over the
face area (vertices 0-9408, the ICT "face" block) whose control points are the 68 landmarks
(active, direct; jaw line, chin and lower lip attached to the jaw) and fixed anchors around the
area's border; everything else is still. It has the resolution and control point count of a real
rig, which is what the benchmark measures.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .face import Face, load_face
from .rig import ControlPoint, Region, Rig, RigidPart

FACE_AREA = 9409
JAW_LANDMARKS = list(range(3, 14)) + [55, 56, 57, 58, 59, 65, 66, 67]
BORDER_ANCHORS = 24


def ict_face_and_rig(root: Path | None = None) -> tuple[Face, Rig] | None:
    """The ICT face and its benchmark rig, or None when the assets are absent."""
    from .bench import shared_assets

    folder = (root or shared_assets()) / "ict_facekit"
    mesh, indices = folder / "generic_neutral_mesh.obj", folder / "vertex_indices.json"
    if not (mesh.is_file() and indices.is_file()):
        return None
    face = load_face(mesh)
    face.name = "ict"
    landmarks = json.loads(indices.read_text())["idx_to_landmark_verts"]
    return face, landmark_rig(face, landmarks)


def landmark_rig(face: Face, landmarks: list[int]) -> Rig:
    """One DFFD region over the face area driven by the landmark vertices (module docstring)."""
    v = face.vertices
    area = np.arange(min(FACE_AREA, len(v)))
    points = [
        ControlPoint(f"lm{i}", v[idx].copy(), "active", vertex=int(idx),
                     attach="jaw" if i in JAW_LANDMARKS else None)
        for i, idx in enumerate(landmarks)
    ]
    points += _border_anchors(v, area, set(landmarks))
    rest = np.setdiff1d(np.arange(len(v)), area).astype(np.int32)
    jaw_pivot = (v[landmarks[0]] + v[landmarks[16]]) / 2 - np.array([0.0, 0.1, 0.0]) * np.ptp(v[area, 1])
    head_pivot = jaw_pivot - np.array([0.0, 0.2, 0.3]) * np.ptp(v[area, 1])
    regions = [Region("face", "dffd", area.astype(np.int32), [p.name for p in points])]
    if len(rest):
        regions.append(Region("rest", "still", rest))
    return Rig(
        n_vertices=len(v),
        control_points=points,
        regions=regions,
        rigid_parts={"jaw": RigidPart("jaw", jaw_pivot, axis=np.array([1.0, 0.0, 0.0])),
                     "head": RigidPart("head", head_pivot)},
    )


def _border_anchors(v: np.ndarray, area: np.ndarray, taken: set[int]) -> list[ControlPoint]:
    """Fixed anchors on the area's outermost vertices, one per angular sector around its centre."""
    p = v[area]
    centre = p.mean(axis=0)
    angle = np.arctan2(p[:, 1] - centre[1], p[:, 0] - centre[0])
    radius = np.linalg.norm((p - centre)[:, :2], axis=1)
    sector = ((angle + np.pi) / (2 * np.pi) * BORDER_ANCHORS).astype(int) % BORDER_ANCHORS
    anchors = []
    for s in range(BORDER_ANCHORS):
        inside = np.flatnonzero(sector == s)
        if len(inside):
            idx = int(area[inside[np.argmax(radius[inside])]])
            if idx not in taken:
                anchors.append(ControlPoint(f"anchor{s}", v[idx].copy(), "fixed", vertex=idx))
    return anchors
