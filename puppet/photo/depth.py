"""The camera and the shape in depth of a face from one photo.

A detector such as MediaPipe Face Mesh gives each landmark a depth beside its pixel (``z``:
pixel scale at the face, smaller is nearer, its zero unknown). With a pin-hole camera the pixel
and the depth together give the landmark's place in 3D (``PhotoCamera.lift``), which undoes the
lens's perspective: the nose, nearer the camera, is drawn larger than the ears, and an
orthographic fit (a photo read as a parallel projection) takes that for the face's shape.

The camera's focal length is rarely known: a photo's EXIF 35 mm-equivalent focal length gives
it when the photo is as the camera took it (``focal_from_exif``); otherwise the camera is taken
to stand ``DISTANCE`` face widths away, a portrait at about a metre (a 14 cm wide face).

The face is then brought onto the lifted landmarks by a similarity in 3D (``Similarity3``,
least squares: scale, the head's turn, position) and, after the shape model has shaped it
(``puppet.photo.shapemodel``), a smooth warp (``Warp3``) takes what the model leaves: a
thin-plate spline in 3D taking the face's landmark points onto the landmarks, smoothed as much
as the landmarks' error calls for, with anchors on the back of the head and the neck that it
leaves where the similarity puts them, so that the face's local shape does not spread over the
skull.

A detector's depth is a weak cue (``DEPTH_TRUST``): the landmarks are lifted at the face's own
depth, moved that fraction of the way toward the detector's.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RBFInterpolator

from puppet.face.model import Face

DISTANCE = 7.0  # camera distance in face widths when the photo does not say: a portrait at ~1 m
FULL_FRAME_DIAGONAL = 43.27  # mm, the 35 mm film frame's diagonal (EXIF 35 mm-equivalent focal)
XY_SMOOTHING = 1e-5  # thin-plate spline smoothing of x, y for exact landmarks, face units squared
Z_SMOOTHING = 1e-3  # the same for depth
SMOOTHING = 300.0
"""The thin-plate spline's smoothing of x and y per squared landmark error (face units): a
detector's landmarks (``LANDMARK_NOISE``) are followed loosely, exact ones closely. 100 to 1000
do alike on held-out MakeHuman faces (``tools/checks/shape_check.py``); the larger, the less a
detector's scatter shows."""
DEPTH_TRUST = 0.05
"""How far the landmarks' depth goes from the face's own toward a detector's. MediaPipe's
depth is poor on faces it was not trained on: on renders of held-out MakeHuman faces it errs
3.9% of the face width RMS against their true depth, whose differences from the default face's
are about 1% (``tools/checks/shape_check.py``), and on the rendered ICT face 4.15% against the default
face's own 3.07% (``tools/checks/photo_check.py``). Trusted 0.3, it turned the fitted head (a depth
error is a turn of the head) and made the held-out faces worse than the generic one; 0.05 does
a little better than none on them. ICT's face, further from the default, gains from it (its
face area 0.90x the generic face's trusted fully, 1.00x at 0.05), but a photo cannot tell which
kind of face it shows: MediaPipe's depth disagrees with the default face's by 3.8% of the width
on the ICT render, no more than its own error on the MakeHuman faces; nor does it help through
the shape model (fitted to the detector's depth, the ICT face's eye sockets deepen)."""
LANDMARK_NOISE = 0.02
"""A detector's error on a landmark's place, in face widths: MediaPipe on renders of held-out
MakeHuman faces is off the point it marks on the default face by 0.7% to 1.6% (median to the
outline's), a third of it the same on every face. Exact landmarks (a check's) are given less."""
ANCHORS = 48  # points on the back of the head and the neck the warp keeps


@dataclass
class PhotoCamera:
    """A pin-hole camera looking along -z of the photo frame (x right, y up, z toward the
    camera), ``focal`` pixels, its axis through ``centre`` (pixels, x right, y down).

    Points are in pixels at the reference depth z = 0 (where one unit shows as one pixel)."""

    focal: float
    centre: np.ndarray

    def lift(self, pixels: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """The 3D points (M, 3) that show at ``pixels`` (M, 2) with photo-frame ``depth`` (M,)."""
        grow = 1.0 - np.asarray(depth, float) / self.focal
        offset = (np.asarray(pixels, float) - self.centre) * [1.0, -1.0]
        return np.c_[offset * grow[:, None], depth]

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels (M, 2) where photo-frame points (M, 3) show."""
        shrink = self.focal / (self.focal - points[:, 2])
        return self.centre + points[:, :2] * shrink[:, None] * [1.0, -1.0]


def focal_from_exif(path: str | os.PathLike) -> float | None:
    """The focal length in pixels from a photo's EXIF 35 mm-equivalent focal length, when the
    image is the size the camera recorded (not cropped or resized); else None."""
    from PIL import Image

    try:
        with Image.open(path) as image:
            exif = image.getexif().get_ifd(0x8769)  # the Exif IFD
            size = image.size
    except OSError:
        return None
    equivalent = exif.get(0xA405)  # FocalLengthIn35mmFilm
    recorded = (exif.get(0xA002), exif.get(0xA003))  # PixelXDimension, PixelYDimension
    if not equivalent or recorded != size:
        return None
    return float(equivalent) * float(np.hypot(*size)) / FULL_FRAME_DIAGONAL


@dataclass
class Similarity3:
    """q = scale * R @ p + t: face frame -> photo frame."""

    scale: float
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)

    def apply(self, p: np.ndarray) -> np.ndarray:
        return self.scale * np.asarray(p, float) @ self.rotation.T + self.translation

    def inverse(self, q: np.ndarray) -> np.ndarray:
        return (np.asarray(q, float) - self.translation) @ self.rotation / self.scale

    def after(self, inner: Similarity3) -> Similarity3:
        """This similarity applied after ``inner``."""
        return Similarity3(self.scale * inner.scale, self.rotation @ inner.rotation,
                           self.scale * self.rotation @ inner.translation + self.translation)

    def angles(self) -> dict[str, float]:
        """The head's turn in degrees: yaw (about y, + toward the face's left), pitch (about x,
        + chin up), roll (about z)."""
        R = self.rotation
        return {"yaw": float(np.degrees(np.arcsin(np.clip(R[0, 2], -1, 1)))),
                "pitch": float(np.degrees(np.arctan2(-R[1, 2], R[2, 2]))),
                "roll": float(np.degrees(np.arctan2(-R[0, 1], R[0, 0])))}


def similarity_3d(source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None) -> Similarity3:
    """Least-squares similarity (Umeyama, no reflection) taking ``source`` (M, 3) onto
    ``target`` (M, 3), each pair weighted by ``weights`` (M,) if given."""
    w = np.ones(len(source)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    ms, mt = w @ source, w @ target
    a, b = source - ms, target - mt
    u, sig, vt = np.linalg.svd((b * w[:, None]).T @ a)
    d = np.array([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rotation = u @ np.diag(d) @ vt
    scale = float((sig * d).sum() / (w @ (a ** 2).sum(axis=1)))
    return Similarity3(scale, rotation, mt - scale * rotation @ ms)


@dataclass
class Warp3:
    """A smooth displacement of the face frame taking ``sites`` to their targets: thin-plate
    splines in 3D, one for x, y and one (smoother) for depth."""

    xy: RBFInterpolator
    z: RBFInterpolator

    def __call__(self, p: np.ndarray) -> np.ndarray:
        """Warped points (M, 3)."""
        p = np.asarray(p, float)
        return p + np.c_[self.xy(p), self.z(p)]

    def jacobian(self, p: np.ndarray, step: float = 1e-3) -> np.ndarray:
        """The warp's 3x3 Jacobian at one point (3,), by central differences."""
        probes = p + np.vstack([np.eye(3), -np.eye(3)]) * step
        moved = self(probes)
        return ((moved[:3] - moved[3:]) / (2 * step)).T


def face_width(face: Face) -> float:
    """The width of ``face``'s oval (its ``face_oval`` contour, across x): the unit a photo's
    errors, smoothings and distances are measured in."""
    return float(np.ptp(face.vertices[face.contours["face_oval"], 0]))


def fit_warp(face: Face, sites: np.ndarray, targets: np.ndarray, noise: float = LANDMARK_NOISE) -> Warp3:
    """The warp taking ``sites`` (M, 3, on ``face``) to ``targets`` (M, 3), the face's hidden
    head held still (``back_anchors``), x and y smoothed as much as landmarks erring by ``noise``
    face widths call for (``SMOOTHING``; 0: through the landmarks)."""
    anchors = back_anchors(face)
    points = np.vstack([sites, anchors])
    shift = np.vstack([targets - sites, np.zeros_like(anchors)])
    smoothing = XY_SMOOTHING + SMOOTHING * (noise * face_width(face)) ** 2
    xy = RBFInterpolator(points, shift[:, :2], kernel="thin_plate_spline", smoothing=smoothing)
    z = RBFInterpolator(points, shift[:, 2:], kernel="thin_plate_spline", smoothing=Z_SMOOTHING)
    return Warp3(xy, z)


def back_anchors(face: Face) -> np.ndarray:
    """Points of the head a frontal photo does not show, which the warp keeps where the
    similarity puts them: ``ANCHORS`` skin vertices spread over the head behind the ears and
    the neck below the jaw (farthest-point sampling), and the skull's outline seen from the
    front above the eyes (the farthest skin vertex from the eyes' mid-point in each 15 degree
    sector from 30 to 150 degrees). Without them the spline's extrapolation carries the
    brows' or the forehead's shape over the skull."""
    v = face.vertices[face.parts["skin"]]
    ear = face.feature_points["10.10"][2] if "10.10" in face.feature_points else face.pivots["head"][2]
    chin = face.feature_points["2.1"]
    hidden = v[(v[:, 2] < ear) | ((v[:, 1] < chin[1] - 0.1 * np.ptp(v[:, 1])) & (v[:, 2] < chin[2]))]
    chosen = [int(np.argmin(hidden[:, 1]))]
    distance = np.linalg.norm(hidden - hidden[chosen[0]], axis=1)
    for _ in range(ANCHORS - 1):
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(hidden - hidden[chosen[-1]], axis=1))
    centre = (face.feature_points["3.7"] + face.feature_points["3.12"]) / 2
    d = v[:, :2] - centre[:2]
    angle = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    radius = np.linalg.norm(d, axis=1)
    outline = [v[np.flatnonzero(s)[np.argmax(radius[s])]]
               for lo in range(30, 150, 15) if (s := (angle >= lo) & (angle < lo + 15)).any()]
    return np.vstack([hidden[chosen], outline])
