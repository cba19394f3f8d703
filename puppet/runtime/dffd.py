"""Weighted Dirichlet free-form deformation (DFFD) of one functional region.

Every query (a region's vertices, and the passive control points it drives) gets exact Sibson
coordinates x_i with respect to the region's control points plus the 8 corners of the region's
bounding box enlarged by ``box_scale`` (the corners only make every query lie strictly inside the
sites' hull; they weigh 0). The weighted coefficients of the paper's formula (2),

    c_i = w_i x_i / sum_k w_k x_k,

map control point displacements to query displacements: dv = sum_k c_k dp_k. Because the corners
weigh 0 the coefficients of the real control points sum to 1, so translating every control point
translates the region, and a direct control point (a site on a vertex) moves its vertex by exactly
its own displacement (Sibson's Lagrange property). Fixed control points, displacement 0, are what
damps the motion toward a region's border.

Box size: the corners' weight is 0 whatever the size, but they still take their share of each
query's natural-neighbour volume; 1.5 half-extents keeps their share small (see SIBSON.md, pitfall
5) while leaving room for the skin to move before it would leave the box.

Real-time mode (``rebase``): when control points have moved far from where the coefficients were
computed, the coefficients are recomputed for the current control points and query positions. A
row changes only if its query moved or if a moved control point is its natural neighbour before or
after the move (a site that is no natural neighbour leaves the query's Voronoi cell and stolen
volumes untouched), so only those rows are recomputed; the result equals a fresh computation.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from puppet.errors import PuppetError
from puppet.face.landmarks import is_fdp
from puppet.runtime.sibson import SibsonError, natural_neighbour_mask, sibson_coordinates


class DffdError(PuppetError, ValueError):
    """A region whose coefficients cannot be computed; the message names the region and the row."""


def box_corners(points: np.ndarray, scale: float) -> np.ndarray:
    """The 8 corners of the points' bounding box, each half-extent scaled by ``scale``.

    A thin axis is first widened to half the longest one, so that skin moving off a flat region's
    surface still has room inside the box.
    """
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2
    half = np.maximum((hi - lo) / 2, 0.5 * max(float((hi - lo).max()) / 2, 1e-12)) * scale
    signs = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)]) * 2 - 1
    return centre + signs * half


def weighted_coefficients(sibson: sp.csr_matrix, weights: np.ndarray, region: str = "") -> sp.csr_matrix:
    """Formula (2): drop the box columns (weight 0), weight, normalise each row to sum 1."""
    k = len(weights)
    weighted = sibson[:, :k] @ sp.diags(np.asarray(weights, dtype=float))
    total = np.asarray(weighted.sum(axis=1)).ravel()
    empty = np.flatnonzero(total <= 1e-12)
    if len(empty):
        raise DffdError(
            f"region {region!r}: {len(empty)} queries (first row {empty[0]}) have only box corners "
            "as natural neighbours; add control points (fixed anchors) near them"
        )
    return sp.csr_matrix(sp.diags(1.0 / total) @ weighted)


class RegionDeformer:
    """Coefficient matrix of one region: rows = queries, columns = the region's control points."""

    def __init__(self, name: str, queries: np.ndarray, sites: np.ndarray, weights: np.ndarray,
                 box_scale: float = 1.5, names: list[str] | None = None) -> None:
        self.name, self.names = name, names
        self.box_scale = box_scale
        self.weights = np.asarray(weights, dtype=float)
        self.box = box_corners(np.vstack([queries, sites]), box_scale)
        self.queries = np.array(queries, dtype=float)
        self.sites = np.array(sites, dtype=float)
        self.sibson = self._sibson(self.queries, self.sites)
        self.coefficients = weighted_coefficients(self.sibson, self.weights, name)

    @classmethod
    def from_matrices(cls, name: str, queries: np.ndarray, sites: np.ndarray, weights: np.ndarray,
                      box: np.ndarray, sibson: sp.csr_matrix, box_scale: float = 1.5) -> RegionDeformer:
        """Rebuild a deformer from cached matrices without recomputing Sibson coordinates."""
        self = cls.__new__(cls)
        self.name, self.weights, self.box = name, np.asarray(weights, float), np.asarray(box, float)
        self.names = None
        self.box_scale = box_scale
        self.queries, self.sites = np.array(queries, float), np.array(sites, float)
        self.sibson = sp.csr_matrix(sibson)
        self.coefficients = weighted_coefficients(self.sibson, self.weights, name)
        return self

    def rebase(self, queries: np.ndarray, sites: np.ndarray) -> np.ndarray:
        """Recompute the coefficients for new query and site positions; return the rows redone."""
        queries = np.asarray(queries, dtype=float)
        sites = np.asarray(sites, dtype=float)
        if not self._room_for(np.vstack([queries, sites])):
            return self._rebuild(queries, sites)
        moved_sites = np.flatnonzero(np.any(sites != self.sites, axis=1))
        rows = np.any(queries != self.queries, axis=1)
        if len(moved_sites):
            rows |= np.asarray((self.sibson[:, moved_sites] != 0).sum(axis=1)).ravel() > 0
            try:
                rows |= natural_neighbour_mask(queries, np.vstack([sites, self.box]), moved_sites)
            except SibsonError as exc:
                raise self._error(exc) from None
        redo = np.flatnonzero(rows)
        if len(redo):
            fresh = self._sibson(queries[redo], sites)
            self.sibson = _replace_rows(self.sibson, redo, fresh)
            self.coefficients = weighted_coefficients(self.sibson, self.weights, self.name)
        self.queries, self.sites = queries.copy(), sites.copy()
        return redo

    def _room_for(self, points: np.ndarray) -> bool:
        """Whether the points stay well inside the box (a quarter of its margin to spare)."""
        lo, hi = self.box.min(axis=0), self.box.max(axis=0)
        slack = (hi - lo) * (1 - 1 / self.box_scale) / 8
        return bool(np.all(points > lo + slack) and np.all(points < hi - slack))

    def _rebuild(self, queries: np.ndarray, sites: np.ndarray) -> np.ndarray:
        """The skin has moved toward the box's walls: a new box around it, every row redone."""
        self.box = box_corners(np.vstack([queries, sites]), self.box_scale)
        self.queries, self.sites = queries.copy(), sites.copy()
        self.sibson = self._sibson(self.queries, self.sites)
        self.coefficients = weighted_coefficients(self.sibson, self.weights, self.name)
        return np.arange(len(queries))

    def _sibson(self, queries: np.ndarray, sites: np.ndarray) -> sp.csr_matrix:
        try:
            return sibson_coordinates(queries, np.vstack([sites, self.box]))
        except SibsonError as exc:
            raise self._error(exc) from None

    def _error(self, exc: SibsonError) -> DffdError:
        """The region's error; sites on one place named by their control points when ``names``
        says them: FDP ids are feature points, to be moved apart in ``puppet pick-landmarks``."""
        real = [(i, j) for i, j in exc.pairs if j < len(self.sites)]
        if not real or self.names is None:
            return DffdError(f"region {self.name!r}: {exc}")
        a, b = (self.names[k] for k in real[0])
        more = f" ({len(real)} such pairs)" if len(real) > 1 else ""
        if is_fdp(a) and is_fdp(b):
            return DffdError(f"region {self.name!r}: feature points {a} and {b} fall on the same place{more}: "
                             "move one in puppet pick-landmarks and rig again")
        return DffdError(f"region {self.name!r}: control points {a!r} and {b!r} fall on the same place{more}: "
                         "move the landmarks near them apart in puppet pick-landmarks and rig again")


def _replace_rows(matrix: sp.csr_matrix, rows: np.ndarray, new_rows: sp.csr_matrix) -> sp.csr_matrix:
    """``matrix`` with the given rows replaced by ``new_rows`` (same column count)."""
    keep = np.ones(matrix.shape[0], dtype=bool)
    keep[rows] = False
    kept = np.flatnonzero(keep)
    stacked = sp.vstack([matrix[kept], new_rows], format="csr")
    order = np.empty(matrix.shape[0], dtype=np.int64)
    order[np.concatenate([kept, rows])] = np.arange(matrix.shape[0])
    return stacked[order]
