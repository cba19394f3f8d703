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
nearest to where it sits on the reference face (``CreaseReference``), plus ``MARGIN``. Where it
sits is for the caller to say (``puppet.face.motiontransfer``'s thin-plate warp through the shared
feature points).
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
        return self.bend_from(self.dihedral(rest, triangles), posed, triangles)

    def bend_from(self, rest_angles: np.ndarray, posed: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """``bend`` from the rest's dihedral angles, found once for many poses."""
        return wrapped(self.dihedral(posed, triangles) - rest_angles)


def wrapped(angles: np.ndarray) -> np.ndarray:
    """Angle differences (radians) wrapped into (-pi, pi]: a bend through the flat angle is the short way round."""
    return np.pi - np.remainder(np.pi - angles, 2 * np.pi)


@dataclass(frozen=True)
class CreaseReference:
    """A reference face at rest whose bends bound another face's: its interior edges, their hinges
    (eye separations) and where they sit (edge midpoints)."""

    hinges: Hinges
    triangles: np.ndarray
    angles: np.ndarray  # (R,) the reference edges' dihedral angles at rest
    hinge: np.ndarray  # (R,) the reference edges' hinges, eye separations
    places: cKDTree  # the reference edges' midpoints, mesh units

    @classmethod
    def of(cls, rest: np.ndarray, triangles: np.ndarray, eye_separation: float) -> CreaseReference:
        """The reference a mesh at rest sets (its ``eye_separation`` in mesh units)."""
        rest, triangles = np.asarray(rest, float), np.asarray(triangles)
        hinges = Hinges.of(triangles)
        return cls(hinges, triangles, hinges.dihedral(rest, triangles),
                   hinges.hinge_lengths(rest, triangles) / eye_separation, cKDTree(hinges.midpoints(rest)))

    def nearest(self, places: np.ndarray) -> np.ndarray:
        """The ``NEIGHBOURS`` reference edges (E, NEIGHBOURS) nearest to each of these places on
        the reference face (its mesh units): found once, used for every pose."""
        _, nearest = self.places.query(np.asarray(places, float), k=NEIGHBOURS)
        return np.atleast_2d(nearest.T).T

    def allowed(self, posed: np.ndarray, nearest: np.ndarray, hinge: np.ndarray) -> np.ndarray:
        """The largest bend (E,) allowed to edges with these hinges (eye separations) whose
        ``nearest`` reference edges bend as they do with the reference in pose ``posed``."""
        rates = np.abs(self.hinges.bend_from(self.angles, posed, self.triangles)) / np.maximum(self.hinge, 1e-12)
        return hinge * rates[nearest].max(axis=1) + MARGIN


def near_edges(face, hinges: Hinges, point: str, within: float) -> np.ndarray:
    """Mask over ``hinges`` (the face's interior edges): the skin's edges whose midpoints lie within
    ``within`` face widths (the skin's extent in x) of feature point ``point``."""
    rest = np.asarray(face.vertices, float)
    skin = np.zeros(len(rest), dtype=bool)
    skin[face.parts["skin"]] = True
    width = np.ptp(rest[face.parts["skin"], 0])
    distance = np.linalg.norm(hinges.midpoints(rest) - rest[face.feature_vertices[point]], axis=1)
    return (distance < within * width) & skin[hinges.edges].all(axis=1)


def largest_bend_near(face, positions: np.ndarray, points: tuple[str, ...], within: float) -> float:
    """The largest bend (degrees, either way) in ``positions`` of the skin's edges ``near_edges``
    of any of ``points``: a crease where a viewer looks for one (under the eyes in a smile)."""
    rest = np.asarray(face.vertices, float)
    triangles = np.asarray(face.triangles)
    hinges = Hinges.of(triangles)
    near = np.any([near_edges(face, hinges, point, within) for point in points], axis=0)
    bend = hinges.bend(rest, np.asarray(positions, float), triangles)
    return float(np.degrees(np.abs(bend[near]).max(initial=0.0)))
