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
from puppet.runtime.creases import CreaseBound, Hinges, creases
from puppet.runtime.musclesolver import folded_triangles
from puppet.runtime.runtime import Runtime

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


def skin_triangles(face) -> np.ndarray:
    """The triangles whose three corners are on the skin part (every triangle if it has none)."""
    tri = np.asarray(face.triangles)
    if "skin" not in face.parts:
        return tri
    on = np.zeros(len(face.vertices), dtype=bool)
    on[face.parts["skin"]] = True
    return tri[on[tri].all(axis=1)]


def eye_separation(face) -> float:
    """The face's eye separation (ES0 x 1024), mesh units."""
    return face.fapu["ES0"] * 1024


def folded_vertices(runtime: Runtime, poses: dict[str, dict] | None = None) -> np.ndarray:
    """The vertices (sorted) of the triangles that ``poses`` (``POSES`` by default) fold on the
    runtime's face: what a rig's ``guarded`` lists (``puppet.runtime.foldlimits.fold_limited``)."""
    rest, tri = np.asarray(runtime.face.vertices, float), np.asarray(runtime.face.triangles)
    folded = np.zeros(len(tri), dtype=bool)
    for pose in (poses or POSES).values():
        folded |= folded_triangles(rest, runtime.deform_faps(**pose), tri)
    return np.unique(tri[folded])


def pose_flaws(runtime: Runtime, reference: Runtime, poses: dict[str, dict] | None = None) -> dict[str, PoseFlaws]:
    """{pose name: its flaws} on ``runtime``'s face, creases bounded by ``reference`` (the default
    face's runtime) in the same pose; ``poses`` defaults to ``POSES``."""
    face, ref = runtime.face, reference.face
    tri, ref_tri = skin_triangles(face), skin_triangles(ref)
    hinges, ref_hinges = Hinges.of(tri), Hinges.of(ref_tri)
    rest, ref_rest = np.asarray(face.vertices, float), np.asarray(ref.vertices, float)
    es, ref_es = eye_separation(face), eye_separation(ref)
    places = feature_warp(ref.feature_points, face.feature_points)(hinges.midpoints(rest)) / ref_es
    hinge = hinges.hinge_lengths(rest, tri) / es
    out = {}
    for name, pose in (poses or POSES).items():
        posed = runtime.deform_faps(**pose)
        bound = CreaseBound.of(ref_hinges, ref_rest, reference.deform_faps(**pose), ref_tri, ref_es)
        out[name] = PoseFlaws(int(folded_triangles(rest, posed, face.triangles).sum()),
                              int(creases(hinges, rest, posed, tri, bound.at(places, hinge)).sum()),
                              len(hinges.edges))
    return out
