"""Creases: skin that bends sharply along an edge where the artist's face stays smooth.

A fold (``puppet.runtime.musclesolver.folded_triangles``) is a triangle turned over; a crease is
milder and as visible: two neighbouring triangles that keep their sides but hinge about their
shared edge, a ridge across the forehead or a line down the cheek. The measure is per interior
edge (shared by exactly two triangles): its **bend**, the change of the dihedral angle between
the two triangles from rest to the pose (radians, signed angle difference, so a rigid motion
bends nothing and the rest pose is 0 everywhere).

What bend is too much depends on the place and the expression (a smile rightly deepens the
nasolabial fold), so the bound comes from a reference: the default face, whose motions the artist's
shapes calibrated, in the same pose. A dihedral angle grows with the edge's length for the same
curvature, so the reference is a bend *rate*: bend over the hinge (the distance between the two
triangles' centroids), in eye separations of each face. An edge of another face is a crease
when its bend exceeds its hinge times the largest rate among the ``NEIGHBOURS`` reference edges
nearest to where it sits on the reference face, plus ``MARGIN``. Where it sits is for the caller
to say (``puppet.face.motiontransfer``'s thin-plate warp through the shared feature points).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

MARGIN = np.radians(3.0)
"""Bend allowed beyond the reference's, radians: a few degrees no one sees on a lit face."""

NEIGHBOURS = 8
"""Reference edges nearest to an edge's place whose largest bend rate bounds it."""


@dataclass(frozen=True)
class Hinges:
    """The interior edges of a triangle mesh: each edge's vertices and its two triangles."""

    edges: np.ndarray  # (E, 2) vertex indices, in the winding of ``left``
    left: np.ndarray  # (E,) the triangle in which the edge runs edges[:, 0] -> edges[:, 1]
    right: np.ndarray  # (E,) the triangle in which it runs back

    @classmethod
    def of(cls, triangles: np.ndarray) -> Hinges:
        """The edges shared by exactly two consistently wound triangles (others: borders, seams and
        non-manifold edges, are left out)."""
        tri = np.asarray(triangles, dtype=np.int64)
        directed = np.stack([tri, np.roll(tri, -1, axis=1)], axis=2).reshape(-1, 2)
        owner = np.repeat(np.arange(len(tri)), 3)
        n = int(tri.max(initial=-1)) + 1
        key, back = directed[:, 0] * n + directed[:, 1], directed[:, 1] * n + directed[:, 0]
        _, where, counts = np.unique(np.minimum(key, back), return_inverse=True, return_counts=True)
        order = np.argsort(key)
        found = order[np.minimum(np.searchsorted(key, back, sorter=order), len(key) - 1)]
        forward = (counts[where] == 2) & (key[found] == back) & (directed[:, 0] < directed[:, 1])
        return cls(directed[forward], owner[forward], owner[found[forward]])

    def midpoints(self, vertices: np.ndarray) -> np.ndarray:
        """Each edge's midpoint (E, 3)."""
        v = np.asarray(vertices, float)
        return (v[self.edges[:, 0]] + v[self.edges[:, 1]]) / 2

    def hinge_lengths(self, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """The distance between each edge's two triangle centroids (E,)."""
        centroids = np.asarray(vertices, float)[np.asarray(triangles)].mean(axis=1)
        return np.linalg.norm(centroids[self.left] - centroids[self.right], axis=1)

    def dihedral(self, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """Each edge's signed dihedral angle (E,): 0 flat, positive where the surface bends away
        from its front (a ridge), in (-pi, pi]."""
        v = np.asarray(vertices, float)
        tri = np.asarray(triangles)
        normals = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
        n1, n2 = normals[self.left], normals[self.right]
        axis = v[self.edges[:, 1]] - v[self.edges[:, 0]]
        axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
        sine = np.einsum("ij,ij->i", np.cross(n1, n2), axis)
        cosine = np.einsum("ij,ij->i", n1, n2)
        return np.arctan2(sine, cosine)

    def bend(self, rest: np.ndarray, posed: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """The change of each edge's dihedral angle from ``rest`` to ``posed`` (E,), in (-pi, pi]."""
        change = self.dihedral(posed, triangles) - self.dihedral(rest, triangles)
        return np.angle(np.exp(1j * change))


@dataclass(frozen=True)
class CreaseBound:
    """The reference face's bend rates in one pose, where its edges sit: bounds for another face's."""

    places: cKDTree  # reference edge midpoints, in eye separations
    rates: np.ndarray  # |bend| / hinge per reference edge, radians per eye separation

    @classmethod
    def of(cls, hinges: Hinges, rest: np.ndarray, posed: np.ndarray, triangles: np.ndarray,
           eye_separation: float) -> CreaseBound:
        """The bound a reference mesh in pose ``posed`` sets (its ``eye_separation`` in mesh units)."""
        hinge = hinges.hinge_lengths(rest, triangles) / eye_separation
        rates = np.abs(hinges.bend(rest, posed, triangles)) / np.maximum(hinge, 1e-12)
        return cls(cKDTree(hinges.midpoints(rest) / eye_separation), rates)

    def at(self, places: np.ndarray, hinge: np.ndarray) -> np.ndarray:
        """The largest bend (E,) allowed to edges with these hinges (eye separations) at these
        places on the reference face (mesh units of the reference)."""
        _, nearest = self.places.query(np.asarray(places, float), k=NEIGHBOURS)
        return hinge * self.rates[np.atleast_2d(nearest.T).T].max(axis=1) + MARGIN


def creases(hinges: Hinges, rest: np.ndarray, posed: np.ndarray, triangles: np.ndarray,
            allowed: np.ndarray) -> np.ndarray:
    """Boolean mask over ``hinges``' edges bending further than ``allowed`` (E,) radians."""
    return np.abs(hinges.bend(rest, posed, triangles)) > allowed
