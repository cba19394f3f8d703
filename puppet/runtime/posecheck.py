"""Folds and creases of a rigged face in the expressions and visemes, judged against the default face.

A face rigged by transfer (``puppet.face.autorig``, ``puppet.face.motiontransfer``) should show the
six expressions (FAP 2 at intensity 63) and the 15 visemes (FAP 1 at full strength) as the default
face shows them: with no folded triangle (``puppet.runtime.musclesolver.folded_triangles``) and
no crease (``puppet.runtime.creases``) beyond what the default face's own pose bends at the same
place. The place is found by the thin-plate warp through the feature points both faces share
(``puppet.face.motiontransfer.feature_warp``); bends are compared per eye separation (ES0 x 1024)
of each face, so a finer mesh is not blamed for its shorter edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from puppet.face.motiontransfer import feature_warp
from puppet.runtime.creases import CreaseReference, Hinges
from puppet.runtime.forked import forked_map
from puppet.runtime.musclesolver import folded_triangles
from puppet.runtime.runtime import Runtime
from puppet.runtime.skinsmoothing import skin_triangles

EXPRESSIONS = ("joy", "sadness", "anger", "fear", "disgust", "surprise")
POSES = ({name: {"expression": (k, 63, 0, 0)} for k, name in enumerate(EXPRESSIONS, start=1)}
         | {f"viseme {v}": {"viseme": (v, 0, 63)} for v in range(15)})
"""The poses checked: FAP 2 expressions 1..6 at intensity 63 and FAP 1 visemes 0..14 at full strength."""


@dataclass(frozen=True)
class PoseFlaws:
    """What one pose does wrong: folded triangles and creased edges (and the edges checked)."""

    folds: int
    creases: int
    edges: int


def eye_separation(face) -> float:
    """The face's eye separation (ES0 x 1024), mesh units."""
    return face.fapu["ES0"] * 1024


def folded_vertices(runtime: Runtime, poses: dict[str, dict] | None = None) -> np.ndarray:
    """The vertices (sorted) of the triangles that ``poses`` (``POSES`` by default) fold on the
    runtime's face: what a rig's ``guarded`` lists (``puppet.runtime.foldlimits.fold_limited``).
    The poses are deformed on every core (``puppet.runtime.forked``)."""
    rest, tri = np.asarray(runtime.face.vertices, float), np.asarray(runtime.face.triangles)

    def folded(pose: dict) -> np.ndarray:
        return folded_triangles(rest, runtime.deform_faps(**pose), tri)

    return np.unique(tri[np.logical_or.reduce(forked_map(folded, list((poses or POSES).values())))])


class PoseCheck:
    """The poses of a face judged against the reference (the default face's runtime) in the same
    poses: where each edge sits on the reference and what bend it is allowed in each pose are found
    once, for every rig of the face that is checked (``puppet.runtime.creasesmoothing``).

    ``fineness``: each edge's hinge over the mean hinge of the reference edges nearest its place
    (both in eye separations): under 1 where this face's mesh is finer than the reference's."""

    def __init__(self, face, reference: Runtime, poses: dict[str, dict] | None = None) -> None:
        ref = reference.face
        self.reference = reference
        self.poses = poses or POSES
        self.triangles = skin_triangles(face)
        self.hinges = Hinges.of(self.triangles)
        self.rest = np.asarray(face.vertices, float)
        self.rest_angles = self.hinges.dihedral(self.rest, self.triangles)
        self._bound = CreaseReference.of(ref.vertices, skin_triangles(ref), eye_separation(ref))
        places = feature_warp(ref.feature_points, face.feature_points)(self.hinges.midpoints(self.rest))
        self._nearest = self._bound.nearest(places)
        self._hinge = self.hinges.hinge_lengths(self.rest, self.triangles) / eye_separation(face)
        self.fineness = self._hinge / self._bound.hinge[self._nearest].mean(axis=1)
        self._allowed: dict[str, np.ndarray] = {}

    def allowed(self, name: str) -> np.ndarray:
        """The largest bend each edge may show in pose ``name``, from the reference in that pose
        (found on first use, pose by pose: ``fineness`` alone needs none, and a process forked to
        check some poses finds only theirs)."""
        if name not in self._allowed:
            posed = self.reference.deform_faps(**self.poses[name])
            self._allowed[name] = self._bound.allowed(posed, self._nearest, self._hinge)
        return self._allowed[name]

    def excess(self, name: str, posed: np.ndarray) -> np.ndarray:
        """How far each of ``hinges``' edges bends beyond what it is allowed in pose ``name``,
        deformed to ``posed`` (radians; positive where the pose creases it)."""
        return np.abs(self.hinges.bend_from(self.rest_angles, posed, self.triangles)) - self.allowed(name)

    def creased(self, name: str, posed: np.ndarray) -> np.ndarray:
        """Boolean mask over ``hinges``' edges that pose ``name``, deformed to ``posed``, creases."""
        return self.excess(name, posed) > 0

    def flaws(self, runtime: Runtime) -> dict[str, PoseFlaws]:
        """{pose name: its flaws} on ``runtime`` (a rig of this face)."""
        triangles = runtime.face.triangles
        out = {}
        for name, pose in self.poses.items():
            posed = runtime.deform_faps(**pose)
            out[name] = PoseFlaws(int(folded_triangles(self.rest, posed, triangles).sum()),
                                  int(self.creased(name, posed).sum()), len(self.hinges.edges))
        return out


def pose_flaws(runtime: Runtime, reference: Runtime, poses: dict[str, dict] | None = None) -> dict[str, PoseFlaws]:
    """{pose name: its flaws} on ``runtime``'s face, creases bounded by ``reference`` (the default
    face's runtime) in the same pose; ``poses`` defaults to ``POSES``."""
    return PoseCheck(runtime.face, reference, poses).flaws(runtime)
