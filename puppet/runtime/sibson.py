"""Exact 3D Sibson (natural-neighbour) coordinates of many query points.

The Sibson coordinate of a query ``v`` with respect to site ``p_k`` is the volume that the Voronoi
cell of ``v`` would steal from the cell of ``p_k`` if ``v`` were inserted, divided by the volume of
the new cell.  The coordinates are non-negative, sum to one, reproduce linear functions exactly
(``sum_k x_k p_k = v``), equal ``e_j`` at site ``p_j`` and are non-zero only for the natural
neighbours of ``v``.

Method: "old minus new circumcentric subcells".  Inserting ``v`` re-triangulates only its cavity,
the Delaunay tetrahedra whose circumsphere strictly contains ``v``.  The Voronoi cell of a vertex
splits into signed pieces, one per incident tetrahedron (the part of the cell on the tetrahedron's
side, bounded by the edge midpoints, face circumcentres and the circumcentre).  The volume stolen
from ``p_k`` is therefore the sum of its pieces in the cavity tetrahedra minus its pieces in the new
tetrahedra ``(v, f)`` over the cavity's boundary facets ``f``.  The old pieces depend on the sites
only and are computed once per site set; the new pieces reduce to a closed form per new
tetrahedron, evaluated component-wise with numpy for all queries of a chunk at once.  The cavity
is found by testing each query against every circumsphere (one BLAS product per chunk): cheap for
the few hundred tetrahedra of a rig, though the cost grows as queries x tetrahedra.

Why not Watson's formula: it uses the circumcentres of tetrahedra ``(v, e)`` for internal cavity
facets as well, which go to infinity when ``v`` lies in the plane of such a facet; on a
mirror-symmetric face every vertex of the mid-line does exactly that.  Every circumcentre used
here is bounded for a query strictly inside the hull.

Flat tetrahedra: for cospherical sites (cube faces, every mirror pair of a symmetric face) Qhull
emits zero-volume tetrahedra.  A tetrahedron is flat when ``|6V| < 1e-10 * (longest edge)**3``;
it never enters the cavity on its own account, and each new tetrahedron ``(v, f)`` is oriented by
the cavity side of ``f``, never by ``v``.  A connected group of flat tetrahedra (all on one circle)
joins the cavity when every tetrahedron around the group does: the result is the same, but the
nearly flat new tetrahedra with far circumcentres that a query near the circle's plane would
otherwise create are avoided.  The sites are never jittered.

In-sphere test: strict, with a margin relative to the tetrahedron's scale, so a query on a
circumsphere leaves that tetrahedron out; including it would add a zero-volume contribution.

Snap rule: a query within ``1e-8`` of the sites' extent from a site gets that site's Lagrange row
``e_j`` (near a site the accuracy of any exact method degrades as eps * extent / distance).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree

from puppet.errors import PuppetError

FLAT_TOL = 1e-10
"""A tetrahedron is flat when ``|6V| < FLAT_TOL * (longest edge)**3``."""
SNAP_TOL = 1e-8
"""Queries this close to a site (relative to the sites' extent) snap to the site's row."""
HULL_TOL = 1e-10
"""Queries must lie at least this far (relative to the extent) inside the sites' hull."""
DUPLICATE_TOL = 1e-12
"""Sites closer than this (relative to the extent) are duplicates."""
_INSPHERE_TOL = 1e-12
"""In-sphere margin on the power ``r**2 - |v - c|**2``, times ``1 + |c|`` (normalised units)."""
_CHUNK = 512
"""Queries per chunk; keeps the per-chunk work arrays inside the CPU caches."""

# Facet opposite local vertex i, ordered so that (vertex i, facet) keeps the tetrahedron's
# orientation.
_FACETS = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


class SibsonError(PuppetError, ValueError):
    """Invalid input for Sibson coordinates (bad sites, or queries outside their hull). ``pairs``:
    the (k, 2) indices of sites on one place, for a caller that can name them."""

    def __init__(self, message: str, pairs: np.ndarray | None = None) -> None:
        super().__init__(message)
        self.pairs = np.zeros((0, 2), dtype=np.int64) if pairs is None else np.asarray(pairs)


@dataclass(frozen=True)
class _Triangulation:
    """Everything about one site set that does not depend on the queries (normalised units)."""

    center: np.ndarray
    scale: float
    extent: float
    points: np.ndarray
    tets: np.ndarray
    neighbours: np.ndarray
    flat: np.ndarray
    spheres: np.ndarray
    sphere_scale: np.ndarray
    flat_groups: tuple[tuple[np.ndarray, np.ndarray], ...]
    facet_verts: np.ndarray
    facet_data: np.ndarray
    old_pieces: sp.csr_matrix
    hull: np.ndarray
    tree: cKDTree


def sibson_coordinates(queries: np.ndarray, sites: np.ndarray) -> sp.csr_matrix:
    """Exact Sibson coordinates, a float64 CSR matrix (M, N): row i expresses queries[i].

    The stored entries of a row are exactly the natural neighbours of the query (a value may be
    zero in a degenerate tie).  Raises SibsonError for invalid sites, non-finite input, or
    queries not strictly inside the sites' convex hull.
    """
    tri = _prepare(sites)
    vt, snap = _prepare_queries(queries, tri)
    n = len(tri.points)
    spheres = _sphere_rows(tri)
    data, indices = [np.zeros(0)], [np.zeros(0, dtype=np.int64)]
    counts = [np.zeros(1, dtype=np.int64)]
    for start, free in _free_chunks(snap):
        block_snap = snap[start : start + _CHUNK]
        x = np.zeros((len(block_snap), n))
        nat = np.zeros((len(block_snap), n), dtype=bool)
        x_t, nat_t = _chunk_coordinates(vt[:, free], spheres, tri)
        x[free - start], nat[free - start] = x_t.T, nat_t.T
        snapped = np.flatnonzero(block_snap >= 0)
        x[snapped, block_snap[snapped]] = 1.0
        nat[snapped, block_snap[snapped]] = True
        r, c = np.nonzero(nat)
        data.append(x[r, c])
        indices.append(c)
        counts.append(np.count_nonzero(nat, axis=1))
    indptr = np.cumsum(np.concatenate(counts))
    return sp.csr_matrix(
        (np.concatenate(data), np.concatenate(indices), indptr), shape=(len(snap), n)
    )


def natural_neighbour_mask(queries: np.ndarray, sites: np.ndarray, k: int | np.ndarray) -> np.ndarray:
    """Boolean (M,): which queries have a non-zero Sibson coordinate for site ``k`` (or, given
    several indices, for any of them).

    That is, the query lies strictly inside the circumsphere of a non-flat Delaunay tetrahedron
    incident to site k.  Same test, chunking and snap rule as sibson_coordinates, so the mask
    equals the stored pattern of column k there.
    """
    tri = _prepare(sites)
    n = len(tri.points)
    ks = np.atleast_1d(np.asarray(k, dtype=np.int64))
    if ((ks < 0) | (ks >= n)).any():
        raise SibsonError(f"site index k={ks[(ks < 0) | (ks >= n)][0]} out of range for {n} sites")
    vt, snap = _prepare_queries(queries, tri)
    spheres = _sphere_rows(tri)
    incident = np.flatnonzero(np.isin(tri.tets, ks).any(axis=1) & ~tri.flat)
    mask = np.isin(snap, ks)
    for _, free in _free_chunks(snap):
        mask[free] = _inside_spheres(vt[:, free], spheres)[incident].any(axis=0)
    return mask


def _prepare(sites: np.ndarray) -> _Triangulation:
    """Validate the sites and return their (cached) triangulation data."""
    s = _as_points(sites, "sites")
    if len(s) < 5:
        raise SibsonError(f"need at least 5 sites, got {len(s)}")
    return _triangulate(s.tobytes(), len(s))


def _as_points(a: np.ndarray, name: str) -> np.ndarray:
    """float64 (n, 3) copy-if-needed of ``a``; SibsonError for other shapes or non-finite rows."""
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise SibsonError(f"{name} must have shape (n, 3), got {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if len(bad):
        raise SibsonError(
            f"{name} contain non-finite values: {len(bad)} rows, first index {bad[0]}"
        )
    return np.ascontiguousarray(arr)


@lru_cache(maxsize=8)
def _triangulate(raw: bytes, n: int) -> _Triangulation:
    sites = np.frombuffer(raw, dtype=np.float64).reshape(n, 3)
    lo, hi = sites.min(axis=0), sites.max(axis=0)
    _check_sites(sites, float((hi - lo).max()))
    center = 0.5 * (lo + hi)
    scale = float(2.0 ** np.ceil(np.log2((hi - lo).max())))
    points = (sites - center) / scale
    extent = float((points.max(axis=0) - points.min(axis=0)).max())
    try:
        dt = Delaunay(points)
        hull = ConvexHull(points).equations
    except QhullError as err:
        raise SibsonError(f"sites cannot be triangulated: {err}") from err
    if len(dt.coplanar):
        dropped = sorted(dt.coplanar[:, 0].tolist())
        raise SibsonError(f"sites {dropped} are too close to others to triangulate")
    tets = dt.simplices.astype(np.int64)
    det6, flat = _volumes(points, tets)
    local = np.repeat(_FACETS[None], len(tets), axis=0)
    local[det6 < 0] = local[det6 < 0][:, :, [0, 2, 1]]
    facet_verts = np.take_along_axis(tets[:, None, :], local, axis=2).reshape(-1, 3)
    facet_data = _facet_data(points, facet_verts, np.repeat(flat, 4))
    spheres, sscale = _circumspheres(points, tets, det6, flat)
    return _Triangulation(
        center=center,
        scale=scale,
        extent=extent,
        points=points,
        tets=tets,
        neighbours=np.where(dt.neighbors < 0, len(tets), dt.neighbors),
        flat=flat,
        spheres=spheres,
        sphere_scale=sscale,
        flat_groups=_flat_groups(dt.neighbors, flat),
        facet_verts=facet_verts.T.copy(),
        facet_data=facet_data,
        old_pieces=_old_pieces(points, tets, local[:, 0], facet_data[:, ::4], np.abs(det6), flat),
        hull=hull,
        tree=cKDTree(points),
    )


def _check_sites(sites: np.ndarray, extent: float) -> None:
    """Raise SibsonError for duplicate sites or a set without volume."""
    pairs = cKDTree(sites).query_pairs(DUPLICATE_TOL * extent, output_type="ndarray")
    if len(pairs):
        shown = ", ".join(f"{i} and {j}" for i, j in sorted(map(tuple, pairs))[:5])
        raise SibsonError(f"duplicate sites: {len(pairs)} pairs, e.g. indices {shown}",
                          np.array(sorted(map(tuple, pairs))))
    sv = np.linalg.svd(sites - sites.mean(axis=0), compute_uv=False)
    if sv[2] <= 1e-12 * sv[0]:
        raise SibsonError("all sites are coplanar (or collinear); need a 3D point set")


def _volumes(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Six times the signed volume of each tetrahedron, and its flat flag."""
    p = points[tets]
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    det6 = np.einsum("ij,ij->i", e1, np.cross(e2, e3))
    edges = p[:, [1, 2, 3, 2, 3, 3]] - p[:, [0, 0, 0, 1, 1, 2]]
    longest = np.sqrt((edges**2).sum(axis=2).max(axis=1))
    return det6, np.abs(det6) < FLAT_TOL * longest**3


def _circumspheres(
    points: np.ndarray, tets: np.ndarray, det6: np.ndarray, flat: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rows (2c, w) per tetrahedron, power(v) = 2c.v + w - |v|^2 = r^2 - |v - c|^2, and 1 + |c|.

    Flat tetrahedra get c = 0, w = -1e300: no query is ever inside them.
    """
    p = points[tets]
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    num = (
        (e1**2).sum(1)[:, None] * np.cross(e2, e3)
        + (e2**2).sum(1)[:, None] * np.cross(e3, e1)
        + (e3**2).sum(1)[:, None] * np.cross(e1, e2)
    )
    safe = np.where(flat, 1.0, det6)
    c = np.where(flat[:, None], 0.0, p[:, 0] + num / (2.0 * safe[:, None]))
    w = (p[:, 0] ** 2).sum(1) - 2.0 * (p[:, 0] * c).sum(1)
    w[flat] = -1e300
    return np.column_stack([2.0 * c, w]), 1.0 + np.linalg.norm(c, axis=1)


def _facet_data(points: np.ndarray, facet_verts: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """(12, F) per ordered facet (a, b, c): a, b, c and lambda, with n = (b - a) x (c - a):

    lambda_k n = (y - x) x (cc - p_k) for the cyclic pair (x, y) after k, cc the facet's
    circumcentre: four times the vector area of k's Voronoi quad in the facet.  Facets of flat
    tetrahedra are never used and get lambda = 0.
    """
    a, b, c = (points[facet_verts[:, j]] for j in range(3))
    e1, e2 = b - a, c - a
    n = np.cross(e1, e2)
    nn = np.where(flat, 1.0, (n**2).sum(1))[:, None]
    cc = a + np.cross((e1**2).sum(1)[:, None] * e2 - (e2**2).sum(1)[:, None] * e1, n) / (2.0 * nn)
    quads = (np.cross(c - b, cc - a), np.cross(a - c, cc - b), np.cross(b - a, cc - c))
    lam = np.stack([(quad * n).sum(1) for quad in quads], axis=1) / nn
    lam[flat] = 0.0
    return np.hstack([a, b, c, lam]).T.copy()


def _flat_groups(
    neighbours: np.ndarray, flat: np.ndarray
) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Connected groups of flat tetrahedra with the non-flat tetrahedra around them.

    Groups touching the hull are left out: a query strictly inside the hull is never in them.
    """
    idx = np.flatnonzero(flat)
    if not len(idx):
        return ()
    pos = np.full(len(flat) + 1, -1)
    pos[idx] = np.arange(len(idx))
    nb = neighbours[idx]
    r, c = np.nonzero(pos[nb] >= 0)
    graph = sp.coo_matrix((np.ones(len(r)), (r, pos[nb[r, c]])), shape=(len(idx), len(idx)))
    _, label = connected_components(graph, directed=False)
    groups = []
    for g in range(label.max() + 1):
        members = idx[label == g]
        around = np.unique(neighbours[members])
        around = around[(around < 0) | ~flat[around]]
        if len(around) and around[0] >= 0:
            groups.append((members, around))
    return tuple(groups)


def _old_pieces(
    points: np.ndarray,
    tets: np.ndarray,
    local: np.ndarray,
    facet_data: np.ndarray,
    vol6: np.ndarray,
    flat: np.ndarray,
) -> sp.csr_matrix:
    """(2N, T): twelve times each vertex's Voronoi piece per tetrahedron, then 0/1 incidence.

    Pieces of the three vertices of the facet opposite vertex 0 come from _facet_pieces with
    v = vertex 0; vertex 0's piece is the rest of the volume.  Flat tetrahedra get empty rows.
    """
    n = len(points)
    keep = ~flat
    abc = _facet_pieces(points[tets[keep, 0]].T, facet_data[:, keep])
    pieces = np.zeros((len(tets), 4))
    pieces[np.flatnonzero(keep)[:, None], local[keep]] = abc.T
    pieces[keep, 0] = 2.0 * vol6[keep] - abc.sum(axis=0)
    cols = np.repeat(np.flatnonzero(keep), 8)
    rows = np.concatenate([tets[keep], tets[keep] + n], axis=1).ravel()
    vals = np.concatenate([pieces[keep], np.ones((keep.sum(), 4))], axis=1).ravel()
    return sp.csr_matrix((vals, (rows, cols)), shape=(2 * n, len(tets)))


def _prepare_queries(queries: np.ndarray, tri: _Triangulation) -> tuple[np.ndarray, np.ndarray]:
    """(5, M) rows (x, y, z, 1, |v|^2) of the normalised queries; each one's snap site (-1: none).

    Raises SibsonError for queries (not on a site) that are not strictly inside the hull.
    """
    q = _as_points(queries, "queries")
    vn = (q - tri.center) / tri.scale
    snap = np.full(len(vn), -1)
    if not len(vn):
        return np.zeros((5, 0)), snap
    dist, near = tri.tree.query(vn, distance_upper_bound=SNAP_TOL * tri.extent)
    snap[np.isfinite(dist)] = near[np.isfinite(dist)]
    height = (vn @ tri.hull[:, :3].T + tri.hull[:, 3]).max(axis=1)
    outside = np.flatnonzero((height >= -HULL_TOL * tri.extent) & (snap < 0))
    if len(outside):
        i = outside[0]
        raise SibsonError(
            f"{len(outside)} of {len(vn)} queries are not strictly inside the convex hull of the "
            f"{len(tri.points)} sites; first: index {i}, point {q[i].tolist()}"
        )
    vx, vy, vz = vn.T
    return np.stack([vx, vy, vz, np.ones(len(vn)), vx * vx + vy * vy + vz * vz]), snap


def _free_chunks(snap: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
    """Per chunk of _CHUNK queries: its first index and the indices of its non-snapped queries."""
    for start in range(0, len(snap), _CHUNK):
        yield start, start + np.flatnonzero(snap[start : start + _CHUNK] < 0)


def _sphere_rows(tri: _Triangulation) -> np.ndarray:
    """(T, 4) rows (2c, w - margin): inside when row . (v, 1) > |v|^2 (see _circumspheres)."""
    spheres = tri.spheres.copy()
    spheres[:, 3] -= _INSPHERE_TOL * tri.sphere_scale
    return spheres


def _inside_spheres(vt: np.ndarray, spheres: np.ndarray) -> np.ndarray:
    """(T, m) bool: query strictly inside the circumsphere of each tetrahedron."""
    return spheres @ vt[:4] > vt[4]


def _chunk_coordinates(
    vt: np.ndarray, spheres: np.ndarray, tri: _Triangulation
) -> tuple[np.ndarray, np.ndarray]:
    """Transposed (N, m) coordinates and natural-neighbour flags of a chunk of free queries."""
    m, n, n_tets = vt.shape[1], len(tri.points), len(tri.tets)
    inside = _inside_spheres(vt, spheres)
    cavity = np.zeros((n_tets + 1, m), dtype=bool)
    cavity[:n_tets] = inside
    for members, around in tri.flat_groups:
        cavity[members] = inside[around].all(axis=0)
    t, q = np.divmod(np.flatnonzero(inside), m)
    outer = ~cavity.ravel()[tri.neighbours[t] * m + q[:, None]]
    r, i = np.divmod(np.flatnonzero(outer), 4)
    bq, bf = q[r], 4 * t[r] + i
    new = _facet_pieces(vt[:3].take(bq, axis=1), tri.facet_data.take(bf, axis=1))
    new_idx = tri.facet_verts.take(bf, axis=1) * m + bq
    old = tri.old_pieces @ inside.astype(np.float64)
    x = old[:n] - np.bincount(new_idx.ravel(), weights=new.ravel(), minlength=n * m).reshape(n, m)
    np.maximum(x, 0.0, out=x)
    x /= x.sum(axis=0)
    return x, old[n:] > 0.0


def _facet_pieces(v: np.ndarray, facet: np.ndarray) -> np.ndarray:
    """Twelve times the Voronoi pieces of a, b, c in the tetrahedra (v, a, b, c), shape (3, K).

    v is (3, K); facet is (12, K): a, b, c and lambda (see _facet_data).  (v, a, b, c) is taken
    as positively oriented whatever the side of v: this orients each new tetrahedron by the
    cavity side of its facet.  With vectors relative to v, D = det(a, b, c) and circumcentre
    o = O / (2 D), O = |a|^2 b x c + |b|^2 c x a + |c|^2 a x b, the piece of a is
    lambda_a h + mu_ab F(a, b) + mu_ca F(a, c): h = o.n_f - D is the facet term
    (n_f = (b - a) x (c - a) = a x b + b x c + c x a), the faces through v give
    mu_xy = o.(x x y) / |x x y|^2 and F(x, y) = |y|^2 (|x|^2 + x.y) / 2 - (x.y)^2 (the code
    carries mu / 2 and 2 F).
    """
    vx, vy, vz = v
    ax, ay, az = facet[0] - vx, facet[1] - vy, facet[2] - vz
    bx, by, bz = facet[3] - vx, facet[4] - vy, facet[5] - vz
    cx, cy, cz = facet[6] - vx, facet[7] - vy, facet[8] - vz
    aa = ax * ax + ay * ay + az * az
    bb = bx * bx + by * by + bz * bz
    cc = cx * cx + cy * cy + cz * cz
    ab = ax * bx + ay * by + az * bz
    bc = bx * cx + by * cy + bz * cz
    ca = cx * ax + cy * ay + cz * az
    abx, aby, abz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    bcx, bcy, bcz = by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx
    cax, cay, caz = cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax
    det = ax * bcx + ay * bcy + az * bcz
    ox = aa * bcx + bb * cax + cc * abx
    oy = aa * bcy + bb * cay + cc * aby
    oz = aa * bcz + bb * caz + cc * abz
    s_ab = ox * abx + oy * aby + oz * abz
    s_bc = ox * bcx + oy * bcy + oz * bcz
    s_ca = ox * cax + oy * cay + oz * caz
    quarter_inv_det = 0.25 / det
    h = (s_ab + s_bc + s_ca) * (quarter_inv_det + quarter_inv_det) - det
    mu_ab = s_ab * quarter_inv_det / (abx * abx + aby * aby + abz * abz)
    mu_bc = s_bc * quarter_inv_det / (bcx * bcx + bcy * bcy + bcz * bcz)
    mu_ca = s_ca * quarter_inv_det / (cax * cax + cay * cay + caz * caz)
    ab2, bc2, ca2 = ab * ab, bc * bc, ca * ca
    ab2 += ab2
    bc2 += bc2
    ca2 += ca2
    out = np.empty((3, len(vx)))
    out[0] = facet[9] * h + mu_ab * (bb * (aa + ab) - ab2) + mu_ca * (cc * (aa + ca) - ca2)
    out[1] = facet[10] * h + mu_bc * (cc * (bb + bc) - bc2) + mu_ab * (aa * (bb + ab) - ab2)
    out[2] = facet[11] * h + mu_ca * (aa * (cc + ca) - ca2) + mu_bc * (bb * (cc + bc) - bc2)
    return out
