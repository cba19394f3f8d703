"""Fewer triangles over the same vertices: quadric-error edge collapses for levels of detail.

A part that is drawn a few pixels wide (an eyeball, a row of teeth behind the lips) costs a
software rasteriser as much per triangle as the skin does, for detail nobody can see. The
coarser version here keeps the part's own vertices, so whatever moves them (the runtime's rigid
motions, its normals) moves it too: only the triangles change, never a position.

Each collapse takes a vertex ``u`` into a neighbour ``w`` (a half-edge collapse: ``w`` stays
where it is) and is priced by Garland and Heckbert's quadric error, the summed squared distance
from ``w`` to the planes of the triangles that met at both. Collapses run in rounds of many at
once, so the work is numpy over edges rather than a loop over vertices: in a round each
vertex's cheapest allowed collapse among the round's cheaper half competes, and one is taken
only where its rank is the lowest within two edges of its ``u`` (then again among those left,
as in Luby's algorithm), so no two taken collapses touch the same triangles and each round's
checks stay valid. A collapse is allowed when its error stays within ``MAX_ERROR``, when ``u``
is not on an open border or a non-manifold edge, nor (given colours) where one colour meets
another (the edge of an iris stays where it is), when ``u`` and ``w`` share only the neighbours
of the edge's own triangles (no pinched surface), and when no triangle around ``u`` turns by
more than 60 degrees or lands on another.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

MAX_TURN_COS = 0.5
"""A collapse may turn a triangle's normal by at most 60 degrees."""

MAX_ERROR = 0.2
"""A collapse may leave ``w`` at most this share of the part's mean edge length from the planes
it takes over (root mean square, by area): a lash or a tear line lying on an eyeball keeps
its side of it."""

CHOICES = 2
"""Per vertex and round, how many of its cheapest collapses are checked for turned triangles."""

PASSES = 4
"""Per round, how many times the collapses still free pick their local minima (Luby's way to a
nearly maximal set of collapses two edges apart)."""

LEAST_GAIN = 0.005
"""Rounds stop once one removes less than this share of the triangles the part started with."""


def decimate(vertices: np.ndarray, triangles: np.ndarray, keep: float = 0.25,
             colors: np.ndarray | None = None, color_tolerance: float = 0.2,
             max_rounds: int = 60) -> np.ndarray:
    """About ``keep`` of ``triangles`` (F, 3), over the same ``vertices`` (N, 3): a coarser
    surface of the same shape, int32 (M, 3) indices into ``vertices``. Stops earlier where no
    allowed collapse is left (``colors`` (N, 3) in 0-1 keeps colour borders)."""
    used, local = np.unique(np.asarray(triangles, dtype=np.int64), return_inverse=True)
    positions = np.asarray(vertices, dtype=np.float64)[used]
    tri = local.reshape(-1, 3)
    start = len(tri)
    target = int(np.ceil(keep * start))
    pinned = _pinned(tri, None if colors is None else np.asarray(colors, dtype=np.float64)[used], color_tolerance)
    quadrics = _quadrics(positions, tri)
    edges = positions[tri[:, [1, 2, 0]]] - positions[tri]
    limit = MAX_ERROR * float(np.linalg.norm(edges, axis=2).mean())
    for _ in range(max_rounds):
        if len(tri) <= target:
            break
        taken_u, taken_w = _round(positions, tri, quadrics, pinned, (len(tri) - target + 1) // 2, limit)
        quadrics[taken_w] += quadrics[taken_u]
        remap = np.arange(len(positions))
        remap[taken_u] = taken_w
        tri = remap[tri]
        tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 2] != tri[:, 0])]
        if 2 * len(taken_u) <= LEAST_GAIN * start:
            break
    return used[tri].astype(np.int32)


def _round(positions: np.ndarray, tri: np.ndarray, quadrics: np.ndarray, pinned: np.ndarray,
           budget: int, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """The collapses (u, w) taken in one round: at most ``budget``, pairwise three edges apart."""
    n = len(positions)
    u, w, shared = _half_edges(tri, n)
    adjacency = sp.csr_matrix((np.ones(len(u)), (u, w)), shape=(n, n))
    u, w, cost = _candidates(positions, tri, quadrics, adjacency, u, w, shared, pinned, limit)
    picked = _spread_out(adjacency, u, cost)
    picked = picked[np.argsort(cost[picked], kind="stable")[:max(budget, 1)]]
    return u[picked], w[picked]


def _candidates(positions: np.ndarray, tri: np.ndarray, quadrics: np.ndarray, adjacency: sp.csr_matrix,
                u: np.ndarray, w: np.ndarray, shared: np.ndarray, pinned: np.ndarray,
                limit: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of the half-edges (u, w), each ``u``'s cheapest allowed collapse (module docstring) among
    the cheaper half, with its quadric error: sorted by ``u``, one row per ``u``."""
    allowed = ~pinned[u]
    allowed &= np.asarray(adjacency[u].multiply(adjacency[w]).sum(axis=1)).ravel() == shared
    u, w = u[allowed], w[allowed]
    cost = _cost(positions, quadrics, u, w)
    if not len(cost):
        return u, w, cost
    area = np.trace(quadrics[u, :3, :3] + quadrics[w, :3, :3], axis1=1, axis2=2)
    cheap = (cost <= np.median(cost)) & (cost <= limit ** 2 * area)
    order = np.flatnonzero(cheap)[np.lexsort((w[cheap], cost[cheap], u[cheap]))]
    u, w, cost = u[order], w[order], cost[order]
    best = np.arange(len(u)) - np.searchsorted(u, u) < CHOICES  # each u's cheapest few are checked
    u, w, cost = u[best], w[best], cost[best]
    keep = _keeps_surface(positions, tri, u, w, len(positions))
    u, w, cost = u[keep], w[keep], cost[keep]
    first = np.flatnonzero(np.diff(u, prepend=-1))  # each u's cheapest that folds nothing
    return u[first], w[first], cost[first]


def _spread_out(adjacency: sp.csr_matrix, u: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """Rows of ``u`` (distinct vertices) to collapse together: each the cheapest within two edges
    of its vertex among those not yet ruled out, ``PASSES`` times (Luby's algorithm)."""
    free = np.iinfo(np.int64).max
    rank = np.full(adjacency.shape[0], free)
    rank[u] = np.argsort(np.argsort(cost, kind="stable"), kind="stable")
    taken = np.zeros(adjacency.shape[0], dtype=bool)
    for _ in range(PASSES):
        near = _neighbour_min(adjacency, _neighbour_min(adjacency, rank))
        chosen = (rank == near) & (rank < free)
        if not chosen.any():
            break
        taken |= chosen
        rank[_within_two(adjacency, chosen)] = free
    return np.flatnonzero(taken[u])


def _edge_keys(tri: np.ndarray, n: int) -> np.ndarray:
    """Each triangle side as one integer, smaller index first: u * n + w."""
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    return np.minimum(a, b) * n + np.maximum(a, b)


def _half_edges(tri: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every directed edge (u, w) once, with how many triangles hold the undirected edge."""
    keys, count = np.unique(_edge_keys(tri, n), return_counts=True)
    low, high = np.divmod(keys, n)
    return np.concatenate([low, high]), np.concatenate([high, low]), np.concatenate([count, count])


def _pinned(tri: np.ndarray, colors: np.ndarray | None, tolerance: float) -> np.ndarray:
    """Vertices never collapsed: on an open border or a non-manifold edge (an edge not held by two
    triangles) and, given ``colors`` of the vertices, where a neighbour's colour differs by more
    than ``tolerance`` in a channel (collapsing them would move where one colour meets another)."""
    n = int(tri.max()) + 1
    u, w, shared = _half_edges(tri, n)
    pinned = np.zeros(n, dtype=bool)
    pinned[u[shared != 2]] = True
    if colors is not None:
        pinned[u[np.abs(colors[u] - colors[w]).max(axis=1) > tolerance]] = True
    return pinned


def _keeps_surface(positions: np.ndarray, tri: np.ndarray, u: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """Per collapse (u, w): whether every triangle around ``u`` that survives it (does not hold
    ``w``) keeps its normal within 60 degrees once ``u`` is moved onto ``w``, and lands on no
    triangle already there (a tetrahedron's last collapse would fold two onto each other)."""
    incidence = sp.csr_matrix((np.ones(tri.size), (tri.ravel(), np.repeat(np.arange(len(tri)), 3))),
                              shape=(n, len(tri)))
    degree = np.diff(incidence.indptr)
    which = np.repeat(np.arange(len(u)), degree[u])
    starts = incidence.indptr[u]
    offsets = np.arange(len(which)) - np.repeat(np.cumsum(degree[u]) - degree[u], degree[u])
    around = tri[incidence.indices[np.repeat(starts, degree[u]) + offsets]]
    survives = ~(around == w[which, None]).any(axis=1)
    corners = positions[around]
    moved = np.where((around == u[which, None])[:, :, None], positions[w[which]][:, None, :], corners)
    before = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    after = np.cross(moved[:, 1] - moved[:, 0], moved[:, 2] - moved[:, 0])
    dot = np.einsum("ij,ij->i", before, after)
    lengths = np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1)
    renamed = np.sort(np.where(around == u[which, None], w[which, None], around), axis=1)
    existing = np.sort(tri, axis=1)
    doubled = np.isin((renamed[:, 0] * n + renamed[:, 1]) * n + renamed[:, 2],
                      (existing[:, 0] * n + existing[:, 1]) * n + existing[:, 2])
    bad = survives & (~(dot > MAX_TURN_COS * lengths) | doubled)
    return np.bincount(which[bad], minlength=len(u)) == 0


def _quadrics(positions: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Per vertex, the area-weighted sum of its triangles' plane quadrics (N, 4, 4)."""
    a, b, c = (positions[tri[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    area = np.linalg.norm(normal, axis=1)
    unit = normal / np.maximum(area, 1e-300)[:, None]
    planes = np.hstack([unit, -np.einsum("ij,ij->i", unit, a)[:, None]])
    each = 0.5 * area[:, None, None] * planes[:, :, None] * planes[:, None, :]
    quadrics = np.zeros((len(positions), 4, 4))
    for k in range(3):
        np.add.at(quadrics, tri[:, k], each)
    return quadrics


def _cost(positions: np.ndarray, quadrics: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The quadric error of moving ``u`` onto ``w``: ``w``'s squared distance to both planes' sets."""
    point = np.hstack([positions[w], np.ones((len(w), 1))])
    return np.einsum("ij,ijk,ik->i", point, quadrics[u] + quadrics[w], point)


def _within_two(adjacency: sp.csr_matrix, chosen: np.ndarray) -> np.ndarray:
    """Vertices at most two edges from a ``chosen`` one, those included."""
    near = chosen.astype(np.float64)
    for _ in range(2):
        near = near + adjacency @ near
    return near > 0


def _neighbour_min(adjacency: sp.csr_matrix, values: np.ndarray) -> np.ndarray:
    """Per vertex, the least of ``values`` over its neighbours (its own where it has none)."""
    out = values.copy()
    rows = np.repeat(np.arange(adjacency.shape[0]), np.diff(adjacency.indptr))
    np.minimum.at(out, rows, values[adjacency.indices])
    return out
