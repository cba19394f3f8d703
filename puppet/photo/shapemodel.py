"""A morphable model of face shape: the default face plus a weighted sum of shape components that
MakeHuman's own shape modifiers make (``data/shape_model.npz``, built from MakeHuman's CC0 targets
by ``tools/builders/build_shape_model.py``; ``data/SHAPE_MODEL.md`` says how).

A frontal photo fixes where the landmarks are across the image, hardly how deep they are or what
the face does above the brows and round the jaw. The model says which depths, foreheads, jaws and
noses go with what the photo shows, as MakeHuman's modifiers shape people: a weight of 1 is one
standard deviation of a MakeHuman population, so the prior on the weights is a unit normal, and
zero weights are the default face.

``fit_shape`` finds the weights whose face best explains landmarks given in the face frame: x
and y firmly, depth by ``depth_weight`` (a detector's depth is a weak cue), each landmark
allowed its own error (a detector's ``LANDMARK_NOISE`` of the face width; more where the
photo's expression moved it), the weights pulled toward zero by the prior; a regularised linear
least squares, alternating with the similarity that places the face on the landmarks. ``ShapeModel.warp`` carries the skin's offsets to points off the skin
(the eyes' and the mouth's parts, the pivots), smoothly.
"""

from __future__ import annotations

import functools
import importlib.resources
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RBFInterpolator

from puppet.photo.depth import LANDMARK_NOISE, Warp3, similarity_3d

SHAPE_MODEL = "shape_model.npz"
ROUNDS = 3  # alternations of the weights and the similarity that places the face on the landmarks
MISFIT = 0.01
"""How far exact landmarks may sit off the model, in face widths: what its components leave of
a face (of held-out MakeHuman faces, 0.3% RMS on the face) and how differently faces place their
landmarks; a detector's error (``puppet.photo.depth.LANDMARK_NOISE``) adds to it."""
SHAPE_ROUNDS = 2  # shape fits, each followed by lifting the landmarks again at the shaped face's depth
WARP_SITES = 400  # skin vertices the smooth field off the skin passes through


@dataclass(frozen=True)
class ShapeModel:
    """Shape components on a face's vertices: offsets (face units) per unit weight."""

    basis: np.ndarray  # (K, N, 3): every vertex of the face, zero off the skin
    skin: np.ndarray  # (S,) the vertices the model moves
    vertex_count: int
    face_hash: str  # the face's triangles (``puppet.photo.build``): the model fits that face only

    def __len__(self) -> int:
        return len(self.basis)

    def offsets(self, weights: np.ndarray) -> np.ndarray:
        """Every vertex's offset (N, 3) at ``weights`` (K,)."""
        return np.tensordot(np.asarray(weights, float), self.basis, axes=1)

    def warp(self, rest: np.ndarray, weights: np.ndarray) -> Warp3:
        """The model's offsets at ``weights`` as a smooth displacement of space: a thin-plate
        spline through ``WARP_SITES`` skin vertices of ``rest`` (N, 3), for points off the skin."""
        sites = _spread(rest[self.skin], WARP_SITES)
        at = rest[self.skin][sites]
        moved = self.offsets(weights)[self.skin][sites]
        return Warp3(RBFInterpolator(at, moved[:, :2], kernel="thin_plate_spline"),
                     RBFInterpolator(at, moved[:, 2:], kernel="thin_plate_spline"))


@functools.cache
def load_shape_model() -> ShapeModel:
    """The shipped model of the default face."""
    with importlib.resources.files("puppet.data").joinpath(SHAPE_MODEL).open("rb") as file:
        data = np.load(file)
        skin, compact = data["vertices"].astype(np.int64), data["basis"].astype(np.float64)
        count, face_hash = int(data["vertex_count"]), str(data["face_hash"])
    basis = np.zeros((len(compact), count, 3))
    basis[:, skin] = compact
    return ShapeModel(basis, skin, count, face_hash)


def fit_shape(model: ShapeModel, rest: np.ndarray, points, targets: np.ndarray, *,
              depth_weight: float | np.ndarray, noise: float | np.ndarray = LANDMARK_NOISE,
              misfit: float = MISFIT) -> np.ndarray:
    """The weights (K,) whose face best explains landmarks at ``points``
    (``puppet.photo.build.MeshPoints``) on a face at ``rest`` (N, 3), seen at ``targets`` (M, 3,
    face frame, up to a similarity): the most probable under the prior's unit normal. Each
    landmark's depth residual counts ``depth_weight`` (scalar or (M,)) times as much as its x and
    y (0: its depth is not known); a landmark may sit ``noise`` (its own error, scalar or (M,))
    and ``misfit`` (the model's) face widths off the model. Each round solves for the weights
    together with a small similarity, then applies the similarity exactly."""
    sites = points.on(rest)
    rows = np.stack([points.on(b) for b in model.basis])  # (K, M, 3)
    width = float(np.ptp(sites[:, 0]))
    spread = (misfit ** 2 + np.broadcast_to(np.asarray(noise, float) ** 2, len(sites))) * width ** 2
    scale = np.sqrt(np.c_[np.ones((len(sites), 2)), np.broadcast_to(depth_weight, len(sites))] / spread[:, None])
    weights, frame = np.zeros(len(model)), targets
    for _ in range(ROUNDS):
        shaped = sites + np.tensordot(weights, rows, axes=1)
        frame = similarity_3d(shaped, frame).inverse(frame)
        moves = _similarity_moves(shaped)  # (7, M, 3)
        a = (np.concatenate([rows, moves]) * scale).reshape(len(model) + 7, -1).T
        normal = a.T @ a
        normal[:len(model), :len(model)] += np.eye(len(model))
        solved = np.linalg.lstsq(normal, a.T @ ((frame - sites) * scale).ravel(), rcond=None)[0]
        weights = solved[:len(model)]
    return weights


def _similarity_moves(points: np.ndarray) -> np.ndarray:
    """The small moves (7, M, 3) of ``points`` by a similarity: three shifts, three turns, a scale."""
    centred = points - points.mean(axis=0)
    shifts = [np.broadcast_to(e, points.shape) for e in np.eye(3)]
    return np.stack(shifts + [np.cross(e, centred) for e in np.eye(3)] + [centred])


def _spread(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` indices of ``points`` spread evenly over them (farthest-point sampling from the lowest)."""
    chosen = [int(np.argmin(points[:, 1]))]
    distance = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(min(count, len(points)) - 1):
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return np.array(chosen)
