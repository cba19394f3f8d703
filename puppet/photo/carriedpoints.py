"""Feature points MediaPipe has no landmark for (or one the default face puts elsewhere), carried
over from the default face by the warp its 468 landmarks make.

MediaPipe's landmarks (``build.MEDIAPIPE_FDP``) give 42 feature points, 39 of them taken as they
are (the chin and the lid creases are the default face's own: ``OWN_PLACE``); a rig needs the others
too: the jaw line (chin sides 2.11 / 2.12, jaw angles 2.13 / 2.14, on the face oval), cheeks,
ears, hairline. Placed one by one from the frame of three nearest given points
(``puppet.face.landmarks``), these are extrapolated far (the jaw angle lies 9-10% of the face
width from any MediaPipe landmark, the hairline 15-20%) from points that follow MediaPipe's
conventions, not the default face's (its 2.1 is under the chin, MediaPipe's 152 in front of
it): on the default face itself the jaw angle and hairline landed 15-36% of the face width off
its own, on faces of other shapes up to 85%, and the rig is sensitive to them (the face oval runs
through them; the jaw band hangs on them).

Carried instead: where MediaPipe's landmarks lie on the mesh and where they lie on the default face
(``data/mediapipe_map.json``) define a warp, a similarity plus a smooth thin-plate displacement
(``SMOOTHING``) fitted to all landmarks at once; each missing feature point of the default face,
warped, snaps to the nearest skin vertex no other feature point holds. Landmarks that lie more than
``OUTLIER`` face widths off the similarity are left out (on a face far from the default face's
shape, the farther half at most): seen edge-on, MediaPipe puts the face-oval points on the
outline of the view, which is not the default face's place for them (on the default face itself
some lift 40-70% of the face width inward).

On two faces of other shapes (``tools/checks/transfer_check.py --found``: the shape model, two standard
deviations out) the face oval's points now lie within 12% of the face width of the given ones,
and the transfer's residual from found landmarks fell from 0.405 / 0.524 to 0.380 / 0.421 (from
given landmarks: 0.352 / 0.357). On MediaPipe's canonical face, the 14 points its table gives and
MediaPipe does not find lie 6.8% of the face width from them (median; placed: 10.2%).

The chin and the lid creases carried too (``OWN_PLACE``), the found 2.1 lies 6.6-8.2% of the
face width from the given one on those two faces (22-26% from MediaPipe's 152), and the residual
from found landmarks is 0.382 / 0.394 (0.382 / 0.441 with them taken from MediaPipe, after the
default face's incisors moved; the default face's own: 0.298; every 4th ARKit shape, ``--every 4``).
Over all 51 shapes: 0.400 / 0.413 (0.400 / 0.441 taken from MediaPipe; given: 0.351 / 0.357; the
default face's own: 0.299). On ICT-FaceKit, whose given chin
is iBUG's (the chin's front, as MediaPipe's 152), the found 2.1 now lies 12.4% of the face width
under it: its rig from given landmarks is the same, from found ones it creases more (6150
creased edges over the 21 poses against 5495, no folds).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.spatial import cKDTree

from puppet.face.default import default_face
from puppet.face.landmarks import PUPILS, SKIPPED
from puppet.photo.build import MEDIAPIPE_FDP, mediapipe_points
from puppet.photo.depth import similarity_3d

FACE_SIDES = (234, 454)  # MediaPipe's face-side points: their distance is the face width
OUTLIER = 0.08  # face widths off the similarity: a landmark on the view's outline, left out of the warp
SMOOTHING = 10.0  # the thin-plate spline's smoothing, default face units (its face width: 1.45)
ROUNDS = 3  # similarity fits, each without the outliers of the one before
OWN_PLACE = {"2.1", "3.13", "3.14"}
"""Feature points MediaPipe has a landmark for that the default face puts elsewhere, carried like
the rest: its chin 2.1 lies under the chin, MediaPipe's 152 on the chin's front (13% of the face
width apart on the default face itself); its upper-lid creases 3.13 / 3.14 lie in the fold, a
dip seen in depth, not in a picture (MediaPipe's 257 / 27 lie 1.7% off them). Taken from
MediaPipe, the shape-model faces' found 2.1 lay 22-26% of the face width from the given one,
and one face's transfer residual was 0.441 (0.415 with the chin alone carried, 0.394 with the
creases too; module docstring)."""
BEHIND = {"11.4", "11.6"}
"""The top and back of the skull: hidden from the front view ``pick-landmarks`` shows, and no
landmark near them to carry them by (``apply_landmarks`` places them, as before)."""


@functools.cache
def mediapipe_reference() -> np.ndarray:
    """MediaPipe's 468 landmarks on the default face (its face frame)."""
    reference = default_face()
    return mediapipe_points(reference).on(reference.vertices)


def found_fdps() -> dict[int, str]:
    """MediaPipe landmark -> the FDP taken from it (``MEDIAPIPE_FDP`` less ``OWN_PLACE``)."""
    return {i: fdp for i, fdp in MEDIAPIPE_FDP.items() if fdp not in OWN_PLACE}


def carried_fdps() -> list[str]:
    """The feature points carried: the default face's vertex feature points not taken from
    MediaPipe (``found_fdps``), less teeth, tongue (no skin under them), pupils (on the eyeball)
    and ``BEHIND``."""
    given = set(found_fdps().values()) | SKIPPED | set(PUPILS) | BEHIND
    return sorted(set(default_face().feature_vertices) - given)


def carried_points(vertices: np.ndarray, skin: np.ndarray, landmarks: np.ndarray,
                   taken: list[int]) -> dict[str, int]:
    """{FDP id: skin vertex} for ``carried_fdps``: the default face's points warped onto the mesh
    (module docstring). ``vertices``: the mesh's (N, 3); ``skin``: its skin vertex indices;
    ``landmarks``: (468,) the vertex each MediaPipe landmark lies on, -1 where none; ``taken``:
    vertices other feature points hold."""
    reference = mediapipe_reference()
    seen = np.flatnonzero(landmarks >= 0)
    mesh, model = np.asarray(vertices, float)[landmarks[seen]], reference[seen]
    width = np.linalg.norm(np.subtract(*reference[list(FACE_SIDES)]))
    inside = np.ones(len(seen), dtype=bool)
    for _ in range(ROUNDS):
        to_model = similarity_3d(mesh[inside], model[inside])
        offset = to_model.apply(mesh) - model
        distance = np.linalg.norm(offset, axis=1)
        inside = distance <= max(OUTLIER * width, np.median(distance))  # the nearer half at least
    warp = RBFInterpolator(model[inside], offset[inside], kernel="thin_plate_spline", smoothing=SMOOTHING)
    fdps = carried_fdps()
    points = np.array([default_face().feature_points[f] for f in fdps])
    targets = to_model.inverse(points + warp(points))
    free = skin[~np.isin(skin, taken)]
    nearest = cKDTree(np.asarray(vertices, float)[free]).query(targets, k=min(len(free), len(fdps) + 1))[1]
    chosen: dict[str, int] = {}
    for fdp, row in zip(fdps, nearest.reshape(len(fdps), -1)):
        chosen[fdp] = int(next(v for v in free[row] if v not in chosen.values()))
    return chosen
