"""A performer's own face from one frontal photo: the default face shaped to the photo's
landmarks in 3D, its expression taken out, textured by the photo all the way round, ready for
the auto-rig.

Zhou & Liu build the specific face from one frontal photo and 11 feature points; here the
generic (default) face is deformed instead of a PCA model, which keeps its vertex order, parts,
contours and feature points, so ``puppet.face.autorig.build_rig`` rigs the result like the default.

Landmarks (image points, pixels, x right, y down; a third column is depth as MediaPipe gives
it: pixel scale, smaller is nearer) come in three layouts, as files any detector writes
(``read_landmarks``), or found in the photo (``puppet.photo.detect``, MediaPipe):

* ``fdp``: a dict of MPEG-4 FDP id -> [x, y]; at least the 11 of ``FDP11`` (eye corners, nose
  tip and base, mouth corners, chin, face sides at the jaw angles); every other FDP of the
  default face given is used too. ``{"layout": "fdp11", "points": [[x, y] * 11]}`` is the same in
  ``FDP11`` order (the picker writes that).
* ``ibug68``: the 68-point iBUG/300-W layout (dlib, face-alignment, ...), 0-based.
* ``mediapipe468``: MediaPipe Face Mesh, 468 or 478 points (478: with the irises, not used).

Each landmark is a point on the default face (``model_points``, ``MeshPoints``): its FDP's
vertex; for iBUG points without one a point by a stated rule (``ibug_points``); for MediaPipe
where MediaPipe itself finds the landmark on the default face (``data/mediapipe_map.json``,
``tools/builders/build_mediapipe_map.py``).

The fit (``fit_photo``):

1. checks: landmarks inside the image; a 2D similarity's residual (wrong order or layout); a
   frontal face (``check_frontal``: the nose tip off the eyes' mid-line, face halves of unequal
   width, the nose too high or low between eyes and chin are refused);
2. a pin-hole camera (``puppet.photo.depth``): each landmark is lifted into 3D at its depth (the
   detector's; else the default face's), which undoes the lens's perspective; a 3D similarity
   gives the head's pose and brings the landmarks into the face frame;
3. the photo's expression is measured with the rig and taken out (``puppet.photo.neutral``);
4. two smooth 3D warps of the default face: onto the landmarks as photographed (the texture is
   read through it) and onto the landmarks with the expression out (the new face). Rigid parts
   move rigidly (``warp_face``).

The texture (``puppet.photo.texture``): the photo where it shows the face, the performer's skin
colour estimated from it over the sides, back and neck, no seam between them.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.resources
import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from puppet.errors import PuppetError
from puppet.face.folder import TexturedFace
from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.fap.table import N_FAPS, fap
from puppet.photo.depth import (
    DEPTH_TRUST,
    DISTANCE,
    LANDMARK_NOISE,
    PhotoCamera,
    Similarity3,
    Warp3,
    face_width,
    fit_warp,
    focal_from_exif,
    similarity_3d,
)
from puppet.photo.neutral import neutralise
from puppet.photo.shapemodel import SHAPE_ROUNDS, ShapeModel, fit_shape, load_shape_model
from puppet.photo.texture import texture_face

FDP11 = ("3.12", "3.8", "3.11", "3.7", "9.3", "9.15", "8.4", "8.3", "2.1", "2.14", "2.13")
"""The 11 required points, in the order of the ``fdp11`` list form and of the picker."""

FDP11_HINTS = {
    "3.12": "outer corner of the right eye (on the photo's left)",
    "3.8": "inner corner of the right eye",
    "3.11": "inner corner of the left eye (on the photo's right)",
    "3.7": "outer corner of the left eye",
    "9.3": "nose tip",
    "9.15": "base of the nose, above the upper lip, in the middle",
    "8.4": "right mouth corner (on the photo's left)",
    "8.3": "left mouth corner",
    "2.1": "bottom of the chin",
    "2.14": "right jaw angle, on the face outline below the ear (photo's left)",
    "2.13": "left jaw angle, on the face outline below the ear (photo's right)",
}

IBUG_FDP = {
    8: "2.1", 17: "4.6", 19: "4.4", 21: "4.2", 22: "4.1", 24: "4.3", 26: "4.5", 30: "9.3",
    31: "9.4", 33: "9.15", 35: "9.5", 36: "3.12", 39: "3.8", 42: "3.11", 45: "3.7",
    48: "8.4", 50: "8.9", 51: "8.1", 52: "8.10", 54: "8.3", 57: "8.2",
    60: "2.5", 61: "2.7", 62: "2.2", 63: "2.6", 64: "2.4", 65: "2.8", 66: "2.3", 67: "2.9",
}
"""iBUG-68 index (0-based) -> FDP where one matches; the rest follow ``_ibug_points``' rules."""

MEDIAPIPE_FDP = {
    152: "2.1", 13: "2.2", 14: "2.3", 308: "2.4", 78: "2.5", 311: "2.6", 81: "2.7", 402: "2.8",
    178: "2.9", 199: "2.10", 386: "3.1", 159: "3.2", 374: "3.3", 145: "3.4", 263: "3.7",
    133: "3.8", 253: "3.9", 23: "3.10", 362: "3.11", 33: "3.12", 257: "3.13", 27: "3.14",
    336: "4.1", 107: "4.2", 334: "4.3", 105: "4.4", 300: "4.5", 70: "4.6", 0: "8.1", 17: "8.2",
    291: "8.3", 61: "8.4", 269: "8.5", 39: "8.6", 405: "8.7", 181: "8.8", 37: "8.9", 267: "8.10",
    358: "9.1", 129: "9.2", 1: "9.3", 2: "9.15",
}
"""MediaPipe landmark -> FDP: the high/medium rows of the shared CC0 table, nose tip 1."""
MEDIAPIPE_MAP = "mediapipe_map.json"  # MediaPipe's 468 landmarks on the default face (puppet/data)
MAX_RESIDUAL = 0.3  # similarity RMS residual / outer eye-corner distance: else the order is wrong
MAX_NOSE_OFFSET = 0.12  # nose tip off the eyes' mid-line / outer eye-corner distance
MIN_HALF_RATIO = 0.7  # narrower / wider face half, measured from the nose tip
PITCH_RANGE = (0.6, 1.6)  # (eyes to nose tip) / (eyes to chin), relative to the default face


class PhotoFaceError(PuppetError, ValueError):
    """Landmarks or a photo that cannot make a face; the message says what and where."""


@dataclass
class Landmarks:
    """2D image landmarks (pixels, x right, y down) in a named layout."""

    layout: str  # "fdp", "ibug68" or "mediapipe468"
    points: np.ndarray  # (K, 2)
    keys: list  # per point: FDP id (fdp) or the layout's integer index
    depth: np.ndarray | None = None  # (K,): a third column, as MediaPipe's z: pixel scale, smaller is nearer


@dataclass
class Similarity:
    """q = scale * R @ p + t, from face-frame (x, y) to image (x, -y)."""

    scale: float
    rotation: np.ndarray  # (2, 2)
    translation: np.ndarray  # (2,)

    def forward(self, p: np.ndarray) -> np.ndarray:
        """Face-frame (M, 2) -> image pixels (M, 2) as (column, row)."""
        q = self.scale * p @ self.rotation.T + self.translation
        return q * [1.0, -1.0]

    def inverse(self, pixels: np.ndarray) -> np.ndarray:
        """Image pixels (M, 2) -> face-frame (x, y)."""
        q = np.asarray(pixels, float) * [1.0, -1.0]
        return (q - self.translation) @ self.rotation / self.scale


# -- landmark files -----------------------------------------------------------------------------

def read_landmarks(path: str | os.PathLike) -> Landmarks:
    """A landmark JSON file: ``{"layout", "points"}``, a plain list (68: iBUG, 468/478:
    MediaPipe, 11: fdp11) or a dict FDP id -> [x, y]. Errors name the file."""
    return parse_landmarks(read_landmarks_json(path), str(path))


def read_landmarks_json(path: str | os.PathLike):
    """The parsed JSON of a landmark file (``read_landmarks``), unchecked; errors name the file."""
    try:
        return json.loads(Path(path).read_text("utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise PhotoFaceError(f"{path}: cannot read landmarks: {exc}") from None


def parse_landmarks(data, source: str = "<landmarks>") -> Landmarks:
    """Landmarks from parsed JSON (see ``read_landmarks``)."""
    layout = None
    if isinstance(data, dict) and "points" in data:
        layout, data = data.get("layout"), data["points"]
    if isinstance(data, dict):
        keys = list(data)
        unknown = [k for k in keys if k not in load_face().feature_points]
        if unknown:
            raise PhotoFaceError(f"{source}: not MPEG-4 feature point ids of the default face: {unknown}")
        points = _points(list(data.values()), source)
        return Landmarks("fdp", points[:, :2], keys, points[:, 2] if points.shape[1] >= 3 else None)
    points = _points(data, source)
    layout = layout or {11: "fdp11", 68: "ibug68", 468: "mediapipe468", 478: "mediapipe468"}.get(len(points))
    expected = {"fdp11": (11,), "ibug68": (68,), "mediapipe468": (468, 478)}
    if layout not in expected:
        raise PhotoFaceError(f"{source}: {len(points)} points and layout {layout!r}: expected a layout of "
                             f"{sorted(expected)} (11, 68 or 468/478 points) or a dict FDP id -> [x, y]")
    if len(points) not in expected[layout]:
        raise PhotoFaceError(f"{source}: layout {layout} needs {' or '.join(map(str, expected[layout]))} "
                             f"points, got {len(points)}")
    depth = points[:, 2] if points.shape[1] >= 3 else None
    if layout == "fdp11":
        return Landmarks("fdp", points[:, :2], list(FDP11), depth)
    return Landmarks(layout, points[:, :2], list(range(len(points))), depth)


def _points(values, source: str) -> np.ndarray:
    try:
        points = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise PhotoFaceError(f"{source}: points must be [x, y] pairs of numbers") from None
    if points.ndim != 2 or points.shape[1] < 2 or len(points) == 0:
        raise PhotoFaceError(f"{source}: points must be a non-empty list of [x, y] pairs")
    if not np.isfinite(points[:, :3]).all():
        raise PhotoFaceError(f"{source}: points must be finite numbers")
    return points[:, :3]  # x, y, and MediaPipe's z where given


def check_inside(landmarks: Landmarks, size: tuple[int, int]) -> None:
    """Refuse landmarks outside the image of ``size`` (width, height), naming them."""
    width, height = size
    p = landmarks.points
    outside = np.flatnonzero((p[:, 0] < 0) | (p[:, 0] > width) | (p[:, 1] < 0) | (p[:, 1] > height))
    if len(outside):
        named = ", ".join(f"{landmarks.keys[i]} at ({p[i, 0]:.0f}, {p[i, 1]:.0f})" for i in outside[:5])
        raise PhotoFaceError(f"{len(outside)} landmark(s) outside the {width}x{height} image: {named}")


# -- correspondences on the default face -----------------------------------------------------------

@dataclass
class MeshPoints:
    """Points on a mesh, each a weighted sum of up to three of its vertices: where landmarks sit
    on a face, wherever its vertices move."""

    vertices: np.ndarray  # (M, 3) int
    weights: np.ndarray  # (M, 3), rows summing to 1

    def __len__(self) -> int:
        return len(self.vertices)

    def on(self, positions: np.ndarray) -> np.ndarray:
        """The points (M, 3) on a mesh with these vertex ``positions`` (N, 3)."""
        return np.einsum("mk,mkd->md", self.weights, np.asarray(positions)[self.vertices])

    def take(self, rows) -> MeshPoints:
        return MeshPoints(self.vertices[rows], self.weights[rows])

    @classmethod
    def at(cls, vertices) -> MeshPoints:
        """Points on the given vertices."""
        v = np.asarray(vertices, dtype=np.int64).reshape(-1, 1)
        return cls(np.repeat(v, 3, axis=1), np.tile([1.0, 0.0, 0.0], (len(v), 1)))

    @classmethod
    def stack(cls, parts: list[MeshPoints]) -> MeshPoints:
        return cls(np.vstack([p.vertices for p in parts]), np.vstack([p.weights for p in parts]))


def model_points(face: Face, landmarks: Landmarks) -> tuple[np.ndarray, MeshPoints, dict[str, int], np.ndarray]:
    """(image points (M, 2), their counterparts on ``face`` (``MeshPoints``), role -> row, and
    which landmarks they are (M,)) for the landmarks the face has a counterpart for. Roles
    (FDP ids, ``side_r``/``side_l``) are what ``check_frontal`` measures. Missing required
    points are an error naming them."""
    if landmarks.layout == "fdp":
        missing = [f for f in FDP11 if f not in landmarks.keys]
        if missing:
            raise PhotoFaceError(f"missing required landmark(s) {missing} ({', '.join(FDP11_HINTS[m] for m in missing)})")
        points = MeshPoints.at([_feature_vertex(face, k) for k in landmarks.keys])
        roles = {k: i for i, k in enumerate(landmarks.keys)}
        roles.update(side_r=roles["2.14"], side_l=roles["2.13"])
        return landmarks.points, points, roles, np.arange(len(points))
    if landmarks.layout == "ibug68":
        roles = {fdp: i for i, fdp in IBUG_FDP.items()} | {"side_r": 0, "side_l": 16}
        return landmarks.points, ibug_points(face), roles, np.arange(68)
    index = np.arange(468)
    roles = {fdp: i for i, fdp in MEDIAPIPE_FDP.items()} | {"side_r": 234, "side_l": 454}
    return landmarks.points[index], mediapipe_points(face), roles, index


def _feature_vertex(face: Face, fdp: str) -> int:
    """The vertex of a feature point, or the one nearest it where it has none (the pupils)."""
    if fdp in face.feature_vertices:
        return int(face.feature_vertices[fdp])
    return int(np.argmin(np.linalg.norm(face.vertices - face.feature_points[fdp], axis=1)))


def mediapipe_points(face: Face) -> MeshPoints:
    """MediaPipe Face Mesh's 468 landmarks on the default face (``data/mediapipe_map.json``,
    built by ``tools/builders/build_mediapipe_map.py`` from MediaPipe's canonical face). Only the
    default face's topology has them: another face is refused."""
    table = _mediapipe_map()
    if int(table["vertex_count"]) != len(face.vertices) or table["face_hash"] != _topology_hash(face):
        raise PhotoFaceError(f"face {face.name!r}: MediaPipe landmarks are mapped onto the default face only")
    return MeshPoints(np.array(table["vertices"]), np.array(table["weights"]))


@functools.cache
def _mediapipe_map() -> dict:
    return json.loads(importlib.resources.files("puppet.data").joinpath(MEDIAPIPE_MAP).read_text("utf-8"))


def _topology_hash(face: Face) -> str:
    """A short hash of a face's triangles: the map's vertex indices are valid on that topology."""
    return hashlib.sha256(np.ascontiguousarray(face.triangles, dtype=np.int32).tobytes()).hexdigest()[:16]


def ibug_points(face: Face) -> MeshPoints:
    """The 68 iBUG points on a face of the default topology, by rules:

    * FDPs where ``IBUG_FDP`` names one;
    * jaw 0-16: the face oval from the right side at the outer eye corners' height, down through
      the chin (8) and up the left side, 8 equal arc-length steps on each side;
    * brows 18, 20, 23, 25: the skin vertex nearest the mid-point of the two FDPs beside it;
    * nose bridge 27-29: the front mid-line at the inner eye corners' height, then 1/3 and 2/3 of
      the way down to the nose tip; 32, 34: the skin vertex nearest the mid-point of 9.15 and
      the nose's bottom edge point beside it;
    * lids 37, 38, 40, 41, 43, 44, 46, 47: 1/3 and 2/3 along the lid opening between corners;
    * lips 49, 53: half way along the vermilion border from the corner to the Cupid's bow peak;
      55, 56, 58, 59: 1/3 and 2/3 along the lower border between the corners and 8.2.
    """
    fp, fv = face.feature_points, face.feature_vertices
    rows: dict[int, MeshPoints] = {i: MeshPoints.at([fv[fdp]]) for i, fdp in IBUG_FDP.items()}
    rows.update(enumerate(_jaw_points(face)))
    for i, (a, b) in {18: ("4.6", "4.4"), 20: ("4.4", "4.2"), 23: ("4.1", "4.3"), 25: ("4.3", "4.5"),
                      32: ("9.4", "9.15"), 34: ("9.15", "9.5")}.items():
        rows[i] = MeshPoints.at([_nearest_skin(face, (fp[a] + fp[b]) / 2)])
    top = _midline_vertex(face, (fp["3.8"][1] + fp["3.11"][1]) / 2)
    rows[27] = MeshPoints.at([top])
    for i, f in ((28, 1 / 3), (29, 2 / 3)):
        rows[i] = MeshPoints.at([_midline_vertex(face, face.vertices[top, 1] + f * (fp["9.3"][1] - face.vertices[top, 1]))])
    lids = {"right_lid_opening": ("3.12", "3.8", (37, 38), (41, 40)),
            "left_lid_opening": ("3.11", "3.7", (43, 44), (47, 46))}
    for loop, (a, b, upper, lower) in lids.items():
        for pair, up in ((upper, True), (lower, False)):
            for i, f in zip(pair, (1 / 3, 2 / 3)):
                rows[i] = _along(face, loop, fv[a], fv[b], f, up)
    lips = [(49, "8.4", "8.9", 0.5, True), (53, "8.10", "8.3", 0.5, True),
            (55, "8.3", "8.2", 1 / 3, False), (56, "8.3", "8.2", 2 / 3, False),
            (58, "8.2", "8.4", 1 / 3, False), (59, "8.2", "8.4", 2 / 3, False)]
    for i, a, b, f, up in lips:
        rows[i] = _along(face, "vermilion_border", fv[a], fv[b], f, up)
    return MeshPoints.stack([rows[i] for i in range(68)])


def _jaw_points(face: Face) -> list[MeshPoints]:
    """iBUG 0-16 on the face oval (see ``ibug_points``)."""
    right, left = _side_vertices(face)
    loop = face.contours["face_oval"]
    chin = int(loop[np.argmin(face.vertices[loop, 1])])
    steps = np.linspace(0.0, 1.0, 9)
    return [_along(face, "face_oval", right, chin, f, False) for f in steps] + \
        [_along(face, "face_oval", chin, left, f, False) for f in steps[1:]]


def _side_vertices(face: Face) -> tuple[int, int]:
    """The face oval's vertices at the outer eye corners' height, right (x < 0) then left."""
    loop = np.asarray(face.contours["face_oval"])
    p = face.vertices[loop]
    height = (face.feature_points["3.7"][1] + face.feature_points["3.12"][1]) / 2
    sides = []
    for sign in (-1, 1):
        on_side = np.flatnonzero(sign * p[:, 0] > 0)
        sides.append(int(loop[on_side[np.argmin(np.abs(p[on_side, 1] - height))]]))
    return sides[0], sides[1]


def _along(face: Face, contour: str, a: int, b: int, fraction: float, upper: bool) -> MeshPoints:
    """The point ``fraction`` of the way (arc length) from vertex a to vertex b along a closed
    contour, taking the upper (higher mean y) or lower of its two paths."""
    loop = list(face.contours[contour])
    i, j = loop.index(a), loop.index(b)
    n = len(loop)
    forward = [loop[(i + k) % n] for k in range((j - i) % n + 1)]
    backward = [loop[(i - k) % n] for k in range((i - j) % n + 1)]
    paths = sorted((forward, backward), key=lambda path: face.vertices[path, 1].mean())
    path = paths[1] if upper else paths[0]
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(face.vertices[path], axis=0), axis=1))]
    s = int(np.clip(np.searchsorted(arc, fraction * arc[-1], side="right") - 1, 0, len(path) - 2))
    t = float(np.clip((fraction * arc[-1] - arc[s]) / max(arc[s + 1] - arc[s], 1e-12), 0.0, 1.0))
    return MeshPoints(np.array([[path[s], path[s + 1], path[s]]]), np.array([[1.0 - t, t, 0.0]]))


def _nearest_skin(face: Face, point: np.ndarray) -> int:
    skin = face.parts["skin"]
    return int(skin[np.argmin(np.linalg.norm(face.vertices[skin] - point, axis=1))])


def _midline_vertex(face: Face, height: float) -> int:
    """The front mid-line skin vertex (x = 0, in front of the inner eye corners' depth minus
    a margin) nearest ``height``."""
    skin = face.parts["skin"]
    v = face.vertices[skin]
    width = np.ptp(v[:, 0])
    front = np.flatnonzero((np.abs(v[:, 0]) < 1e-3 * width) & (v[:, 2] > face.feature_points["3.8"][2] - 0.1 * width))
    return int(skin[front[np.argmin(np.abs(v[front, 1] - height))]])


# -- the fit -------------------------------------------------------------------------------------

def similarity_2d(source: np.ndarray, target: np.ndarray) -> Similarity:
    """Least-squares similarity (Umeyama, no reflection) taking ``source`` (M, 2) onto
    ``target`` (M, 2)."""
    ms, mt = source.mean(axis=0), target.mean(axis=0)
    a, b = source - ms, target - mt
    u, sig, vt = np.linalg.svd(b.T @ a)
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    rotation = u @ d @ vt
    scale = float(np.trace(np.diag(sig) @ d) / (a ** 2).sum())
    return Similarity(scale, rotation, mt - scale * rotation @ ms)


def check_frontal(target: np.ndarray, model: np.ndarray, roles: dict[str, int]) -> dict[str, float]:
    """Measures of a frontal layout on the landmarks in the face frame (``target`` (M, 2)),
    compared with the default face's (``model``); an error names the measure that fails."""
    def measures(p: np.ndarray) -> dict[str, float]:
        r, l, nose, chin = (p[roles[k]] for k in ("3.12", "3.7", "9.3", "2.1"))
        eyes = np.linalg.norm(l - r)
        mid = (l + r) / 2
        half_l, half_r = p[roles["side_l"], 0] - nose[0], nose[0] - p[roles["side_r"], 0]
        return {"nose_offset": float((nose[0] - mid[0]) / eyes),
                "half_ratio": float(min(half_l, half_r) / max(half_l, half_r, 1e-12)),
                "nose_height": float((mid[1] - nose[1]) / max(mid[1] - chin[1], 1e-12))}
    got, ref = measures(target), measures(model[:, :2])
    got["pitch_ratio"] = got["nose_height"] / ref["nose_height"]
    if abs(got["nose_offset"] - ref["nose_offset"]) > MAX_NOSE_OFFSET:
        raise PhotoFaceError(f"not a frontal face: the nose tip is {got['nose_offset']:+.2f} eye-widths off the "
                             f"eyes' mid-line (at most {MAX_NOSE_OFFSET}): the head is turned")
    if got["half_ratio"] < MIN_HALF_RATIO:
        raise PhotoFaceError(f"not a frontal face: the face halves' width ratio is {got['half_ratio']:.2f} "
                             f"(at least {MIN_HALF_RATIO}): the head is turned")
    if not PITCH_RANGE[0] <= got["pitch_ratio"] <= PITCH_RANGE[1]:
        raise PhotoFaceError(f"not a frontal face: the nose sits at {got['pitch_ratio']:.2f} times the default "
                             f"face's height between eyes and chin (allowed {PITCH_RANGE}): the head is tilted")
    return got


@dataclass
class PhotoFit:
    """The default face fitted to a photo's landmarks: the camera, the head's pose in it, the
    face's own shape (the shape model's weights and the face they make), and the warps of that
    face onto the landmarks as the photo shows them and with its expression removed."""

    camera: PhotoCamera
    similarity: Similarity3  # face frame -> photo frame: the head's scale, turn and place
    shape: np.ndarray  # (K,) the shape model's weights (``puppet.photo.shapemodel``); empty without a model
    shaped: Face  # the default face as the model shapes it
    posed: Warp3  # the shaped face onto the landmarks as photographed
    neutral: Warp3  # the same with the expression measured in ``faps`` taken out
    faps: np.ndarray  # (68,) the photo's expression, FAPU, as the default face's rig shows it
    report: dict

    def pixels(self, points: np.ndarray) -> np.ndarray:
        """Where face-frame points (M, 3) show in the photo (M, 2)."""
        return self.camera.project(self.similarity.apply(points))

    def face(self, *, posed: bool = False) -> Face:
        """The new face, its expression taken out; or as photographed (``posed``)."""
        return warp_face(self.shaped, self.posed if posed else self.neutral)


def fit_photo(face: Face, landmarks: Landmarks, size: tuple[int, int], *, focal: float | None = None,
              neutral: bool = True, depth_trust: float = DEPTH_TRUST, landmark_noise: float = LANDMARK_NOISE,
              shape: bool = True) -> PhotoFit:
    """Fit ``face`` (the default face) to ``landmarks`` in an image of ``size`` (width, height)
    seen by a camera of ``focal`` pixels (``puppet.photo.depth``: else a portrait distance). The
    landmarks' depth, where they have one, counts ``depth_trust`` against the face's own (0: not
    at all, 1: as exact); their places are taken to err by ``landmark_noise`` face widths. With
    ``neutral`` the photo's expression is measured and taken out (``puppet.photo.neutral``); with
    ``shape`` the face's own shape comes from the shape model (``puppet.photo.shapemodel``; the
    default face's topology only) before a smooth warp takes what the model leaves. Bad landmarks
    are a ``PhotoFaceError``."""
    check_inside(landmarks, size)
    pixels, points, roles, rows = model_points(face, landmarks)
    model = points.on(face.vertices)
    flat, residual, frontal = _checked(landmarks.layout, pixels, model, roles)
    width = face_width(face)
    camera = PhotoCamera(focal or DISTANCE * width * flat.scale, np.asarray(size, float) / 2)
    depth = None if landmarks.depth is None else -landmarks.depth[rows]
    trust = 0.0 if depth is None else depth_trust
    similarity, targets = _lift(camera, pixels, depth, trust, model, flat.scale)
    faps, relaxed = np.zeros(N_FAPS), targets
    if neutral:
        faps, relaxed = neutralise(face, points, targets, roles)
        # an open jaw tilts the head's fitted pose: take it from the face with the expression out
        correction = similarity_3d(model, relaxed)
        similarity = similarity.after(correction)
        targets, relaxed = correction.inverse(targets), correction.inverse(relaxed)
    weights, shaped = np.zeros(0), face
    shapes = _shape_model(face) if shape else None
    if shapes is not None:
        expression = targets - relaxed
        # a landmark the expression moved is known, once it is taken out, only as well as that move
        noise = landmark_noise + np.linalg.norm(expression, axis=1) / width
        for _ in range(SHAPE_ROUNDS):  # the shape, then the landmarks lifted again at its depth
            weights = fit_shape(shapes, face.vertices, points, relaxed, depth_weight=trust, noise=noise)
            similarity, targets = _lift(camera, pixels, depth, trust,
                                        points.on(face.vertices + shapes.offsets(weights)) + expression, flat.scale)
            relaxed = targets - expression
        shaped = warp_face(face, shapes.warp(face.vertices, weights),
                           skin=(face.vertices + shapes.offsets(weights))[face.parts["skin"]])
    report = {"layout": landmarks.layout, "landmarks": len(pixels), "pixels_per_unit": similarity.scale,
              "focal_pixels": camera.focal, "focal_given": focal is not None,
              "depth_from_landmarks": depth is not None, "head_degrees": similarity.angles(),
              "similarity_residual": residual, "frontal": frontal,
              "shape_weights": np.round(weights, 3).tolist(),
              "expression_faps": {fap(n).name: round(float(faps[n - 1]), 1) for n in range(1, N_FAPS + 1)
                                  if abs(faps[n - 1]) >= 0.05}}
    sites = points.on(shaped.vertices)
    # the face as photographed goes through the landmarks, so that the photo's lips and eyes land on
    # its own; the new face's shape is smoothed as much as the landmarks' error calls for
    return PhotoFit(camera, similarity, weights, shaped, fit_warp(shaped, sites, targets, 0.0),
                    fit_warp(shaped, sites, relaxed, landmark_noise), faps, report)


def _shape_model(face: Face) -> ShapeModel | None:
    """The shape model if ``face`` has the default face's topology (the model's), else None."""
    shapes = load_shape_model()
    if shapes.vertex_count != len(face.vertices) or shapes.face_hash != _topology_hash(face):
        return None
    return shapes


def _checked(layout: str, pixels: np.ndarray, model: np.ndarray,
             roles: dict[str, int]) -> tuple[Similarity, float, dict[str, float]]:
    """(the 2D similarity of the model points onto the landmarks, its residual in eye widths,
    the frontal measures), or a ``PhotoFaceError``: landmarks in the wrong order or layout (a
    large residual), or a face that is not frontal (which also misfits a little: said first)."""
    flat = similarity_2d(model[:, :2], pixels * [1.0, -1.0])
    eyes = np.linalg.norm(model[roles["3.7"], :2] - model[roles["3.12"], :2])
    residual = float(np.sqrt(((flat.inverse(pixels) - model[:, :2]) ** 2).sum(axis=1).mean()) / eyes)
    misfit = PhotoFaceError(f"the landmarks do not fit a face in layout {layout} (residual {residual:.2f} "
                            f"eye-widths after a similarity, at most {MAX_RESIDUAL}): wrong order, mirrored, "
                            "or another layout")
    if residual > 2 * MAX_RESIDUAL:
        raise misfit
    frontal = check_frontal(flat.inverse(pixels), model, roles)
    if residual > MAX_RESIDUAL:
        raise misfit
    return flat, residual, frontal


def _lift(camera: PhotoCamera, pixels: np.ndarray, depth: np.ndarray | None, trust: float, points: np.ndarray,
          scale: float) -> tuple[Similarity3, np.ndarray]:
    """The head's pose and the landmarks in the face frame (M, 3), lifted by the camera at the
    depth of the face's own landmark ``points`` (M, 3, face frame; ``scale`` pixels per unit at
    first, then in the pose fitted to them), moved ``trust`` of the way toward the landmarks' own
    ``depth`` where they have one (its unknown zero at the mean). The pose is fitted twice."""
    own = scale * (points[:, 2] - points[:, 2].mean())
    for _ in range(2):
        guess = own if depth is None else own + trust * (depth - depth.mean() - (own - own.mean()))
        lifted = camera.lift(pixels, guess)
        similarity = similarity_3d(points, lifted)
        own = similarity.apply(points)[:, 2]
    return similarity, similarity.inverse(lifted)


# -- the new face --------------------------------------------------------------------------------

def warp_face(face: Face, warp: Warp3, skin: np.ndarray | None = None) -> Face:
    """``face`` moved by ``warp``: skin by the warp (or to ``skin``, its new positions where they
    are known, as the shape model knows them), eyeballs, teeth and tongue rigidly (each
    eyeball round, set behind its lid opening as on the default face and scaled with the
    opening's width, so a depth the lids and the eye's centre disagree on never pushes it
    through the lids; teeth and tongue together by the warp's local linear map at their
    centroid); feature points and pivots follow. Vertex order, triangles, parts and contours
    are kept."""
    v = warp(face.vertices)
    if skin is not None:
        v[face.parts["skin"]] = skin
    points = {k: warp(p[None])[0] for k, p in face.feature_points.items()}
    pivots = {k: (p if k == "jaw_axis" else warp(p[None])[0]) for k, p in face.pivots.items()}
    for eye, pupil, lids in (("eye_l", "3.5", "left_lid_opening"), ("eye_r", "3.6", "right_lid_opening")):
        ring, new_ring = face.vertices[face.contours[lids]], v[face.contours[lids]]
        scale = np.ptp(new_ring[:, 0]) / np.ptp(ring[:, 0])
        centre = face.pivots[eye]
        pivots[eye] = new_ring.mean(axis=0) + scale * (centre - ring.mean(axis=0))
        v[face.parts[eye]] = pivots[eye] + scale * (face.vertices[face.parts[eye]] - centre)
        points[pupil] = pivots[eye] + scale * (face.feature_points[pupil] - centre)
    mouth = np.concatenate([face.parts[p] for p in ("teeth_upper", "teeth_lower", "tongue") if p in face.parts])
    centre = face.vertices[mouth].mean(axis=0)
    v[mouth] = warp(centre[None])[0] + (face.vertices[mouth] - centre) @ warp.jacobian(centre).T
    for k, i in face.feature_vertices.items():
        points[k] = v[i].copy()
    return Face(name=face.name, vertices=v, triangles=face.triangles.copy(),
                parts={k: p.copy() for k, p in face.parts.items()}, feature_points=points,
                feature_vertices=dict(face.feature_vertices), pivots=pivots,
                contours={k: c.copy() for k, c in face.contours.items()},
                colors=None if face.colors is None else face.colors.copy(),
                source_index=None if face.source_index is None else face.source_index.copy())


def face_from_photo(photo: np.ndarray, landmarks: Landmarks, name: str = "photo", *, focal: float | None = None,
                    neutral: bool = True) -> tuple[TexturedFace, dict]:
    """The default face fitted to ``photo`` (H, W, 3 uint8) by ``landmarks`` (``fit_photo``),
    its expression taken out where ``neutral``, textured by the photo as the face shows in it
    (``puppet.photo.texture``); and the report of the fit and texture."""
    base = load_face()
    fit = fit_photo(base, landmarks, (photo.shape[1], photo.shape[0]), focal=focal, neutral=neutral)
    shown = fit.similarity.apply(fit.face(posed=True).vertices)
    face, report = texture_face(fit.face(), shown, fit.camera, photo, name)
    return face, fit.report | report


def read_photo(path: str | os.PathLike) -> np.ndarray:
    """A photo as (H, W, 3) uint8 RGB; a file that is no image is a ``PhotoFaceError``."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"))
    except (OSError, UnidentifiedImageError) as exc:
        raise PhotoFaceError(f"{path}: cannot read the photo: {exc}") from None


def build_face_folder(photo_path: str | os.PathLike, landmarks_path: str | os.PathLike | None,
                      out: str | os.PathLike, step: Callable[[int, int, str], None] | None = None) -> Path:
    """``puppet face-from-photo``: fit, texture, write ``out`` (``puppet.face.folder``) and rig the
    written face with its fold limits (``fold_limited``). With no
    ``landmarks_path`` the landmarks are detected (``puppet.photo.detect``); the camera's focal
    length comes from the photo's EXIF where it says it (``puppet.photo.depth.focal_from_exif``).
    ``step(k, n, what)`` hears each of the ``n`` steps as it starts."""
    from puppet.face.autorig import build_rig
    from puppet.face.folder import FACE_RIG, load_face_folder, write_face_folder
    from puppet.face.rig import save_rig
    from puppet.photo.detect import detect_landmarks
    from puppet.runtime.foldlimits import fold_limited

    step = step or (lambda k, n, what: None)
    photo = read_photo(photo_path)  # the inputs checked before any step is said
    if landmarks_path is None:
        step(1, 4, f"finding the face's landmarks in {photo_path} (MediaPipe)")
        landmarks = parse_landmarks(detect_landmarks(photo_path), f"{photo_path} (detected landmarks)")
    else:
        landmarks = read_landmarks(landmarks_path)
        step(1, 4, f"{len(landmarks.points)} landmarks read from {landmarks_path}")
    step(2, 4, "fitting the face's shape to the landmarks, the expression taken out, and its texture")
    face, report = face_from_photo(photo, landmarks, Path(photo_path).stem, focal=focal_from_exif(photo_path))
    folder = write_face_folder(face, out, source_photo=str(photo_path), report=report)
    written = load_face_folder(folder)
    step(3, 4, "regions, control points and muscles")
    rig = build_rig(written)
    step(4, 4, "fold limits: how far each FAP goes before a triangle folds (the longest step)")
    save_rig(fold_limited(written, rig), folder / FACE_RIG)
    return folder
