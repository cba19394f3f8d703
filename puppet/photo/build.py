"""A performer's own face from one frontal photo: the default face warped to the photo's
landmarks, textured by the photo, ready for the auto-rig.

Zhou & Liu build the specific face from one frontal photo and 11 feature points; here the
generic (default) face is deformed instead of a PCA model, which keeps its vertex order, parts,
contours and feature points, so ``puppet.face.autorig.build_rig`` rigs the result like the default.

Landmarks (2D image points, pixels, x right, y down) come in three layouts, as files any detector
writes (``read_landmarks``):

* ``fdp``: a dict of MPEG-4 FDP id -> [x, y]; at least the 11 of ``FDP11`` (eye corners, nose
  tip and base, mouth corners, chin, face sides at the jaw angles); every other FDP of the
  default face given is used too. ``{"layout": "fdp11", "points": [[x, y] * 11]}`` is the same in
  ``FDP11`` order (the picker writes that).
* ``ibug68``: the 68-point iBUG/300-W layout (dlib, face-alignment, ...), 0-based.
* ``mediapipe468``: MediaPipe Face Mesh, 468 or 478 points (478: with the irises).

Each landmark has a 3D counterpart on the default face (``model_points``): its FDP, or for iBUG
points without one a point by a stated rule (``_ibug_points``); MediaPipe uses the FDPs of
``MEDIAPIPE_FDP`` (the high and medium confidence rows of the CC0 table in
``shared/assets/mediapipe_face``, with the common nose tip 1 for 9.3) and the face sides 234/454.

The fit (``fit_photo``), in orthographic frontal projection (a portrait lens is nearly that):

1. a similarity (scale, in-plane rotation, translation; least squares) from the model points'
   x, y to the image points (y flipped, since +y is up on the face); its inverse brings the
   landmarks into the face frame, so the new face keeps the default's units and size;
2. a thin-plate spline warp of x, y (``scipy.interpolate.RBFInterpolator``, a little smoothing
   against detector noise) taking the model points onto the landmarks, with anchors on the
   skull's outline and the neck held where the similarity puts them; behind the ears the warp
   fades to its affine part, so the back of the head (which projects onto the face) is not
   given the face's local detail;
3. depth scaled by the warp's mean scale (sqrt of its affine part's determinant): a plausible
   depth, since one photo does not show it;
4. rigid parts move rigidly: each eyeball about its centre with the warp's local mean scale (it
   stays round), teeth and tongue together by the warp's local affine map at their centroid.

Non-frontal layouts are refused (``check_frontal``): the nose tip off the eyes' mid-line, the
two face halves of unequal width, or the nose placed too high or low between eyes and chin.

Texture: each vertex is projected into the photo by the fitted similarity (its ``uv``). A
per-vertex texture weight says how much of the photo to show: 1 on the skin inside the face oval
facing the camera and on the eyeballs inside the lid openings, fading to 0 across a band at the
oval and as the surface turns away; elsewhere (under the chin, the sides, the back, the teeth)
the vertex colour shows: the default face's colours toned to the median colour of the photo's
cheeks (the fall-back skin tone). ``puppet.view.renderer`` mixes the two per pixel.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import RBFInterpolator

from puppet.errors import PuppetError
from puppet.face.folder import TexturedFace
from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.runtime.normals import VertexNormals

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
MEDIAPIPE_IRIS_FDP = {473: "3.5", 468: "3.6"}  # iris centres, only in the 478-point form
MEDIAPIPE_SIDES = {234: "side_r", 454: "side_l"}  # the face outline at the eyes' height

SIDE_KEYS = {"ibug68": (0, 16), "mediapipe468": (234, 454)}
SMOOTHING = 1e-4  # thin-plate spline smoothing, face units squared
MAX_RESIDUAL = 0.3  # similarity RMS residual / outer eye-corner distance: else the order is wrong
MAX_NOSE_OFFSET = 0.12  # nose tip off the eyes' mid-line / outer eye-corner distance
MIN_HALF_RATIO = 0.7  # narrower / wider face half, measured from the nose tip
PITCH_RANGE = (0.6, 1.6)  # (eyes to nose tip) / (eyes to chin), relative to the default face
TEXTURE_MAX = 1024  # longest side of texture.png, pixels
OVAL_BAND = 0.08  # texture fade-out band inside the face oval, fraction of its width
FACING = (0.15, 0.45)  # normal z over which the photo fades in (grazing -> facing the camera)


class PhotoFaceError(PuppetError, ValueError):
    """Landmarks or a photo that cannot make a face; the message says what and where."""


@dataclass
class Landmarks:
    """2D image landmarks (pixels, x right, y down) in a named layout."""

    layout: str  # "fdp", "ibug68" or "mediapipe468"
    points: np.ndarray  # (K, 2)
    keys: list  # per point: FDP id (fdp) or the layout's integer index


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
    try:
        data = json.loads(Path(path).read_text("utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise PhotoFaceError(f"{path}: cannot read landmarks: {exc}") from None
    return parse_landmarks(data, str(path))


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
        return Landmarks("fdp", _points(list(data.values()), source), keys)
    points = _points(data, source)
    layout = layout or {11: "fdp11", 68: "ibug68", 468: "mediapipe468", 478: "mediapipe468"}.get(len(points))
    expected = {"fdp11": (11,), "ibug68": (68,), "mediapipe468": (468, 478)}
    if layout not in expected:
        raise PhotoFaceError(f"{source}: {len(points)} points and layout {layout!r}: expected a layout of "
                             f"{sorted(expected)} (11, 68 or 468/478 points) or a dict FDP id -> [x, y]")
    if len(points) not in expected[layout]:
        raise PhotoFaceError(f"{source}: layout {layout} needs {' or '.join(map(str, expected[layout]))} "
                             f"points, got {len(points)}")
    if layout == "fdp11":
        return Landmarks("fdp", points, list(FDP11))
    return Landmarks(layout, points, list(range(len(points))))


def _points(values, source: str) -> np.ndarray:
    try:
        points = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise PhotoFaceError(f"{source}: points must be [x, y] pairs of numbers") from None
    if points.ndim != 2 or points.shape[1] < 2 or len(points) == 0:
        raise PhotoFaceError(f"{source}: points must be a non-empty list of [x, y] pairs")
    if not np.isfinite(points[:, :2]).all():
        raise PhotoFaceError(f"{source}: points must be finite numbers")
    return points[:, :2]  # MediaPipe writes x, y, z: depth is not used


def check_inside(landmarks: Landmarks, size: tuple[int, int]) -> None:
    """Refuse landmarks outside the image of ``size`` (width, height), naming them."""
    width, height = size
    p = landmarks.points
    outside = np.flatnonzero((p[:, 0] < 0) | (p[:, 0] > width) | (p[:, 1] < 0) | (p[:, 1] > height))
    if len(outside):
        named = ", ".join(f"{landmarks.keys[i]} at ({p[i, 0]:.0f}, {p[i, 1]:.0f})" for i in outside[:5])
        raise PhotoFaceError(f"{len(outside)} landmark(s) outside the {width}x{height} image: {named}")


# -- correspondences on the default face -----------------------------------------------------------

def model_points(face: Face, landmarks: Landmarks) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """(image points (M, 2), their 3D counterparts on ``face`` (M, 3), role -> row) for the
    landmarks the face has a counterpart for. Roles (FDP ids, ``side_r``/``side_l``) are what
    ``check_frontal`` measures. Missing required points are an error naming them."""
    if landmarks.layout == "fdp":
        missing = [f for f in FDP11 if f not in landmarks.keys]
        if missing:
            raise PhotoFaceError(f"missing required landmark(s) {missing} ({', '.join(FDP11_HINTS[m] for m in missing)})")
        model = np.array([face.feature_points[k] for k in landmarks.keys])
        roles = {k: i for i, k in enumerate(landmarks.keys)}
        roles.update(side_r=roles["2.14"], side_l=roles["2.13"])
        return landmarks.points, model, roles
    if landmarks.layout == "ibug68":
        model = _ibug_points(face)
        roles = {fdp: i for i, fdp in IBUG_FDP.items()} | {"side_r": 0, "side_l": 16}
        return landmarks.points, model, roles
    table = dict(MEDIAPIPE_FDP) | (MEDIAPIPE_IRIS_FDP if len(landmarks.points) == 478 else {})
    sides = _side_points(face)
    index = list(table) + list(MEDIAPIPE_SIDES)
    model = np.array([face.feature_points[table[i]] for i in table] + [sides[0], sides[1]])
    roles = {fdp: row for row, fdp in enumerate(table.values())}
    roles.update(side_r=len(table), side_l=len(table) + 1)
    return landmarks.points[index], model, roles


def _ibug_points(face: Face) -> np.ndarray:
    """The 68 iBUG points on a face of the default topology (3D, face frame), by rules:

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
    out = np.zeros((68, 3))
    for i, fdp in IBUG_FDP.items():
        out[i] = fp[fdp]
    out[0:17] = _jaw_points(face)
    for i, (a, b) in {18: ("4.6", "4.4"), 20: ("4.4", "4.2"), 23: ("4.1", "4.3"), 25: ("4.3", "4.5"),
                      32: ("9.4", "9.15"), 34: ("9.15", "9.5")}.items():
        out[i] = _nearest_skin(face, (fp[a] + fp[b]) / 2)
    top = _midline_point(face, (fp["3.8"][1] + fp["3.11"][1]) / 2)
    out[27] = top
    for i, f in ((28, 1 / 3), (29, 2 / 3)):
        out[i] = _midline_point(face, top[1] + f * (fp["9.3"][1] - top[1]))
    lids = {"right_lid_opening": ("3.12", "3.8", (37, 38), (41, 40)),
            "left_lid_opening": ("3.11", "3.7", (43, 44), (47, 46))}
    for loop, (a, b, upper, lower) in lids.items():
        for rows, up in ((upper, True), (lower, False)):
            out[list(rows)] = [_along(face, loop, fv[a], fv[b], f, up) for f in (1 / 3, 2 / 3)]
    lips = [(49, "8.4", "8.9", 0.5, True), (53, "8.10", "8.3", 0.5, True),
            (55, "8.3", "8.2", 1 / 3, False), (56, "8.3", "8.2", 2 / 3, False),
            (58, "8.2", "8.4", 1 / 3, False), (59, "8.2", "8.4", 2 / 3, False)]
    for i, a, b, f, up in lips:
        out[i] = _along(face, "vermilion_border", fv[a], fv[b], f, up)
    return out


def _jaw_points(face: Face) -> np.ndarray:
    """iBUG 0-16 on the face oval (see ``_ibug_points``)."""
    right, left = _side_points(face)
    loop = face.contours["face_oval"]
    chin = int(loop[np.argmin(face.vertices[loop, 1])])
    start, end = (int(loop[np.argmin(np.linalg.norm(face.vertices[loop] - p, axis=1))]) for p in (right, left))
    steps = np.linspace(0.0, 1.0, 9)
    down = [_along(face, "face_oval", start, chin, f, False) for f in steps]
    up = [_along(face, "face_oval", chin, end, f, False) for f in steps[1:]]
    return np.array(down + up)


def _side_points(face: Face) -> tuple[np.ndarray, np.ndarray]:
    """The face oval's vertices at the outer eye corners' height, right (x < 0) then left."""
    loop = face.contours["face_oval"]
    p = face.vertices[loop]
    height = (face.feature_points["3.7"][1] + face.feature_points["3.12"][1]) / 2
    sides = []
    for sign in (-1, 1):
        on_side = np.flatnonzero(sign * p[:, 0] > 0)
        sides.append(p[on_side[np.argmin(np.abs(p[on_side, 1] - height))]])
    return sides[0], sides[1]


def _along(face: Face, contour: str, a: int, b: int, fraction: float, upper: bool) -> np.ndarray:
    """The point ``fraction`` of the way (arc length) from vertex a to vertex b along a closed
    contour, taking the upper (higher mean y) or lower of its two paths."""
    loop = list(face.contours[contour])
    i, j = loop.index(a), loop.index(b)
    n = len(loop)
    forward = [loop[(i + k) % n] for k in range((j - i) % n + 1)]
    backward = [loop[(i - k) % n] for k in range((i - j) % n + 1)]
    paths = sorted((forward, backward), key=lambda path: face.vertices[path, 1].mean())
    p = face.vertices[paths[1] if upper else paths[0]]
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    return np.array([np.interp(fraction * arc[-1], arc, p[:, k]) for k in range(3)])


def _nearest_skin(face: Face, point: np.ndarray) -> np.ndarray:
    skin = face.vertices[face.parts["skin"]]
    return skin[np.argmin(np.linalg.norm(skin - point, axis=1))]


def _midline_point(face: Face, height: float) -> np.ndarray:
    """The front mid-line skin vertex (x = 0, in front of the inner eye corners' depth minus
    a margin) nearest ``height``."""
    skin = face.vertices[face.parts["skin"]]
    width = np.ptp(skin[:, 0])
    front = skin[(np.abs(skin[:, 0]) < 1e-3 * width) & (skin[:, 2] > face.feature_points["3.8"][2] - 0.1 * width)]
    return front[np.argmin(np.abs(front[:, 1] - height))]


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
    """The fitted projection and warp of the default face to a photo's landmarks."""

    similarity: Similarity
    warp: RBFInterpolator  # face-frame (x, y) -> displacement, the full spline
    affine: np.ndarray  # (3, 2): [x, y, 1] @ affine = the least-squares affine displacement
    fade: tuple[float, float]  # z below fade[0]: affine only; above fade[1]: the full spline
    depth_scale: float
    report: dict

    def displacement(self, p: np.ndarray) -> np.ndarray:
        """x, y displacement (M, 2) of face-frame points (M, 3): spline, faded to its affine fit
        behind the face."""
        affine = np.c_[p[:, :2], np.ones(len(p))] @ self.affine
        w = np.clip((p[:, 2] - self.fade[0]) / (self.fade[1] - self.fade[0]), 0.0, 1.0)[:, None]
        return affine + w * (self.warp(p[:, :2]) - affine)

    def apply(self, p: np.ndarray, z_centre: float) -> np.ndarray:
        """Warped points (M, 3): x, y displaced, depth scaled about ``z_centre``."""
        out = np.array(p, dtype=float)
        out[:, :2] += self.displacement(p)
        out[:, 2] = z_centre + self.depth_scale * (p[:, 2] - z_centre)
        return out

    def jacobian(self, p: np.ndarray, step: float = 1e-3) -> np.ndarray:
        """The warp's 2x2 x, y Jacobian at one point (3,), by central differences."""
        cols = []
        for k in range(2):
            d = np.zeros((2, 3))
            d[:, k] = (step, -step)
            moved = p[:2] + d[:, :2] + self.displacement(p + d)
            cols.append((moved[0] - moved[1]) / (2 * step))
        return np.array(cols).T


def _anchors(face: Face) -> np.ndarray:
    """Face-frame x, y of the points the warp keeps where the similarity puts them: the head's
    frontal outline above the eyes (the farthest skin vertex from the eyes' mid-point in each
    15 degree sector from 30 to 150 degrees) and the neck cut's left, right and front. Without
    them the spline's extrapolation stretches the skull after the brows and the neck after the
    chin."""
    skin = face.vertices[face.parts["skin"], :2]
    centre = (face.feature_points["3.7"][:2] + face.feature_points["3.12"][:2]) / 2
    d = skin - centre
    angle = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    radius = np.linalg.norm(d, axis=1)
    outline = [skin[np.flatnonzero(s)[np.argmax(radius[s])]]
               for lo in range(30, 150, 15) if (s := (angle >= lo) & (angle < lo + 15)).any()]
    neck = face.vertices[face.contours["neck_cut"]]
    ends = neck[[np.argmin(neck[:, 0]), np.argmax(neck[:, 0]), np.argmax(neck[:, 2])], :2]
    return np.vstack([outline, ends])


def fit_photo(face: Face, landmarks: Landmarks, size: tuple[int, int]) -> PhotoFit:
    """Fit the similarity and the warp (module docstring) of ``face`` to ``landmarks`` in an
    image of ``size`` (width, height); bad landmarks are a ``PhotoFaceError``."""
    check_inside(landmarks, size)
    pixels, model, roles = model_points(face, landmarks)
    similarity = similarity_2d(model[:, :2], pixels * [1.0, -1.0])
    target = similarity.inverse(pixels)
    eyes = np.linalg.norm(model[roles["3.7"], :2] - model[roles["3.12"], :2])
    residual = float(np.sqrt(((target - model[:, :2]) ** 2).sum(axis=1).mean()) / eyes)
    if residual > MAX_RESIDUAL:
        raise PhotoFaceError(f"the landmarks do not fit a face in layout {landmarks.layout} (residual "
                             f"{residual:.2f} eye-widths after a similarity, at most {MAX_RESIDUAL}): "
                             f"wrong order, mirrored, or another layout")
    frontal = check_frontal(target, model, roles)
    sites = np.vstack([model[:, :2], _anchors(face)])
    shift = np.vstack([target - model[:, :2], np.zeros((len(sites) - len(model), 2))])
    warp = RBFInterpolator(sites, shift, kernel="thin_plate_spline", smoothing=SMOOTHING)
    affine = np.linalg.lstsq(np.c_[sites, np.ones(len(sites))], shift, rcond=None)[0]
    fade = (float(face.pivots["head"][2]), float(min(face.feature_points["10.9"][2], face.feature_points["2.13"][2])))
    report = {"layout": landmarks.layout, "landmarks": len(pixels),
              "pixels_per_unit": similarity.scale,
              "roll_degrees": float(np.degrees(np.arctan2(similarity.rotation[1, 0], similarity.rotation[0, 0]))),
              "similarity_residual": residual, "frontal": frontal}
    depth_scale = float(np.sqrt(abs(np.linalg.det(np.eye(2) + affine[:2]))))
    return PhotoFit(similarity, warp, affine, fade, depth_scale, report)


# -- the new face --------------------------------------------------------------------------------

def warp_face(face: Face, fit: PhotoFit) -> Face:
    """The default face moved by the fit: skin by the warp, eyeballs, teeth and tongue rigidly;
    feature points, pivots follow. Vertex order, triangles, parts and contours are kept."""
    z_centre = float(np.mean([p[2] for p in face.feature_points.values()]))
    v = fit.apply(face.vertices, z_centre)
    points = {k: fit.apply(p[None], z_centre)[0] for k, p in face.feature_points.items()}
    pivots = {k: (p if k == "jaw_axis" else fit.apply(p[None], z_centre)[0]) for k, p in face.pivots.items()}
    for eye, pupil in (("eye_l", "3.5"), ("eye_r", "3.6")):
        centre = face.pivots[eye]
        new_centre = pivots[eye]
        scale = np.sqrt(abs(np.linalg.det(fit.jacobian(centre))))
        v[face.parts[eye]] = new_centre + scale * (face.vertices[face.parts[eye]] - centre)
        points[pupil] = new_centre + scale * (face.feature_points[pupil] - centre)
    mouth = np.concatenate([face.parts[p] for p in ("teeth_upper", "teeth_lower", "tongue") if p in face.parts])
    centre = face.vertices[mouth].mean(axis=0)
    new_centre = fit.apply(centre[None], z_centre)[0]
    local = np.eye(3)
    local[:2, :2] = fit.jacobian(centre)
    local[2, 2] = fit.depth_scale
    v[mouth] = new_centre + (face.vertices[mouth] - centre) @ local.T
    for k, i in face.feature_vertices.items():
        points[k] = v[i].copy()
    return Face(name=face.name, vertices=v, triangles=face.triangles.copy(),
                parts={k: p.copy() for k, p in face.parts.items()}, feature_points=points,
                feature_vertices=dict(face.feature_vertices), pivots=pivots,
                contours={k: c.copy() for k, c in face.contours.items()},
                colors=None if face.colors is None else face.colors.copy(),
                source_index=None if face.source_index is None else face.source_index.copy())


def texture_face(face: Face, fit: PhotoFit, photo: np.ndarray, name: str = "photo") -> TexturedFace:
    """``face`` (warped) with the photo as its texture: uv, texture weights, the photo cropped
    to the head (at most ``TEXTURE_MAX`` pixels) and the fall-back tone in its vertex colours."""
    pixels = fit.similarity.forward(face.vertices[:, :2])
    crop, box = _crop(photo, pixels)
    x0, y0, x1, y1 = box
    uv = np.c_[(pixels[:, 0] - x0) / (x1 - x0), 1.0 - (pixels[:, 1] - y0) / (y1 - y0)]
    inside = ((uv >= 0) & (uv <= 1)).all(axis=1)
    weight = _texture_weight(face) * inside
    tone = _cheek_tone(photo, fit.similarity.forward(np.array([face.feature_points[k][:2] for k in ("5.1", "5.2")])),
                       fit.similarity.scale * np.linalg.norm(face.feature_points["3.7"] - face.feature_points["3.12"]))
    colors = _toned_colors(face, tone)
    fit.report.update(fallback_tone=[round(float(c), 4) for c in tone], textured_vertices=int((weight > 0).sum()),
                      texture_size=[int(crop.shape[1]), int(crop.shape[0])], source_photo=name)
    return TexturedFace(name=name, vertices=face.vertices, triangles=face.triangles, parts=face.parts,
                        feature_points=face.feature_points, feature_vertices=face.feature_vertices,
                        pivots=face.pivots, contours=face.contours, colors=colors,
                        uv=np.clip(uv, 0.0, 1.0).astype(np.float32), triangle_uv=face.triangles.copy(),
                        source_index=face.source_index, texture=crop, texture_weight=weight.astype(np.float32))


def _crop(photo: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The photo cut to the projected head (plus 5%) inside the image, scaled down to at most
    ``TEXTURE_MAX``; and the box (x0, y0, x1, y1) in photo pixels it covers."""
    from PIL import Image

    height, width = photo.shape[:2]
    lo, hi = pixels.min(axis=0), pixels.max(axis=0)
    pad = 0.05 * (hi - lo)
    x0, y0 = (int(np.clip(np.floor(c), 0, m)) for c, m in zip(lo - pad, (width - 1, height - 1)))
    x1, y1 = (int(np.clip(np.ceil(c), lo_ + 1, m)) for c, m, lo_ in zip(hi + pad, (width, height), (x0, y0)))
    crop = Image.fromarray(photo[y0:y1, x0:x1])
    factor = min(1.0, TEXTURE_MAX / max(crop.size))
    if factor < 1.0:
        crop = crop.resize((max(1, round(crop.width * factor)), max(1, round(crop.height * factor))), Image.LANCZOS)
    return np.asarray(crop), (x0, y0, x1, y1)


def _texture_weight(face: Face) -> np.ndarray:
    """Per-vertex photo weight: skin inside the face oval facing the camera, eyeballs inside
    their lid openings (module docstring); 0 elsewhere."""
    v = face.vertices
    normals = VertexNormals(face.triangles, len(v))(v)
    facing = np.clip((normals[:, 2] - FACING[0]) / (FACING[1] - FACING[0]), 0.0, 1.0)
    weight = np.zeros(len(v))
    oval = v[face.contours["face_oval"], :2]
    band = OVAL_BAND * np.ptp(oval[:, 0])
    skin = face.parts["skin"]
    weight[skin] = facing[skin] * np.clip(_inside_distance(oval, v[skin, :2]) / band, 0.0, 1.0)
    for eye, loop in (("eye_l", "left_lid_opening"), ("eye_r", "right_lid_opening")):
        ix = face.parts[eye]
        lid = v[face.contours[loop], :2]
        inside = np.clip(_inside_distance(lid, v[ix, :2]) / (0.1 * np.ptp(lid[:, 0])), 0.0, 1.0)
        weight[ix] = inside * (normals[ix, 2] > 0)
    return weight


def _inside_distance(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (M,) of 2D points to a closed polygon's edges, negative outside it."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    ab = b - a
    t = np.clip(((points[:, None] - a) * ab).sum(-1) / (ab ** 2).sum(-1), 0.0, 1.0)
    d = np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1)
    return np.where(_contains(polygon, points), d, -d)


def _contains(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Even-odd rule: (M,) True for 2D points inside the closed polygon."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    x, y = points[:, None, 0], points[:, None, 1]
    spans = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (spans & (x < cross_x)).sum(axis=1) % 2 == 1


def _cheek_tone(photo: np.ndarray, centres: np.ndarray, eye_width_px: float) -> np.ndarray:
    """Median sRGB colour (0-1) of the photo in discs (radius 0.15 eye widths) at the cheeks."""
    rows, cols = np.mgrid[:photo.shape[0], :photo.shape[1]]
    radius = max(2.0, 0.15 * eye_width_px)
    near = np.zeros(photo.shape[:2], dtype=bool)
    for cx, cy in centres:
        near |= (cols - cx) ** 2 + (rows - cy) ** 2 <= radius ** 2
    return np.median(photo[near][:, :3], axis=0) / 255.0


def _toned_colors(face: Face, tone: np.ndarray) -> np.ndarray:
    """The face's colours with the skin scaled per channel so its cheeks take ``tone``."""
    colors = np.array(face.colors if face.colors is not None else np.full((len(face.vertices), 3), 0.7), np.float32)
    skin = face.parts["skin"]
    cheeks = np.r_[[face.feature_vertices[k] for k in ("5.1", "5.2")]]
    near = np.linalg.norm(face.vertices[skin, None] - face.vertices[cheeks], axis=-1).min(axis=1)
    reference = np.median(colors[skin[np.argsort(near)[:40]]], axis=0)
    colors[skin] = np.clip(colors[skin] * tone / np.maximum(reference, 1e-3), 0.0, 1.0)
    return colors


def face_from_photo(photo: np.ndarray, landmarks: Landmarks, name: str = "photo") -> tuple[TexturedFace, dict]:
    """The default face fitted to ``photo`` (H, W, 3 uint8) by ``landmarks`` and textured, and
    the fit's report (layout, scale, roll, residual, frontal measures, texture)."""
    base = load_face()
    fit = fit_photo(base, landmarks, (photo.shape[1], photo.shape[0]))
    return texture_face(warp_face(base, fit), fit, photo, name), fit.report


def read_photo(path: str | os.PathLike) -> np.ndarray:
    """A photo as (H, W, 3) uint8 RGB; a file that is no image is a ``PhotoFaceError``."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"))
    except (OSError, UnidentifiedImageError) as exc:
        raise PhotoFaceError(f"{path}: cannot read the photo: {exc}") from None


def build_face_folder(photo_path: str | os.PathLike, landmarks_path: str | os.PathLike | None,
                      out: str | os.PathLike) -> Path:
    """``puppet face-from-photo``: fit, texture, write ``out`` (``puppet.face.folder``) and rig the
    written face (rigged from what was written, so the rig matches the face as loaded). With no
    ``landmarks_path`` the landmarks are detected (``puppet.photo.detect``)."""
    from puppet.face.autorig import build_rig
    from puppet.face.folder import FACE_RIG, load_face_folder, write_face_folder
    from puppet.face.rig import save_rig
    from puppet.photo.detect import detect_landmarks

    photo = read_photo(photo_path)
    if landmarks_path is None:
        landmarks = parse_landmarks(detect_landmarks(photo_path), f"{photo_path} (detected landmarks)")
    else:
        landmarks = read_landmarks(landmarks_path)
    face, report = face_from_photo(photo, landmarks, Path(photo_path).stem)
    folder = write_face_folder(face, out, source_photo=str(photo_path), report=report)
    save_rig(build_rig(load_face_folder(folder)), folder / FACE_RIG)
    return folder
