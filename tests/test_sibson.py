"""Exact 3D Sibson coordinates: properties, an independent clipping oracle, errors, masks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull, Delaunay, HalfspaceIntersection, QhullError, Voronoi

from puppet.runtime import sibson
from puppet.runtime.sibson import SibsonError, natural_neighbour_mask, sibson_coordinates

ORACLE_TOL = 1e-9
MODES = ["generic", "mirror", "grid"]


def corners(h: float) -> np.ndarray:
    return h * np.array(
        [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float
    )


# --- independent oracle: clip V'(v) by the old Voronoi cells, volumes by Qhull ----------------


def _clip(points: np.ndarray | None, normal: np.ndarray, offset: float) -> np.ndarray | None:
    """Vertices of conv(points) intersected with {y: y.normal <= offset} (None: empty or flat)."""
    if points is None:
        return None
    s = points @ normal - offset
    if (s <= 0).all():
        return points
    if (s >= 0).all():
        return None
    try:
        hull = ConvexHull(points)
    except QhullError:
        return None
    edges = np.vstack([hull.simplices[:, pair] for pair in ([0, 1], [1, 2], [0, 2])])
    edges = edges[(s[edges[:, 0]] < 0) != (s[edges[:, 1]] < 0)]
    sa, sb = s[edges[:, 0]], s[edges[:, 1]]
    p, q = points[edges[:, 0]], points[edges[:, 1]]
    return np.vstack([points[s < 0], p + (sa / (sa - sb))[:, None] * (q - p)])


def _volume(points: np.ndarray | None) -> float:
    if points is None or len(points) < 4:
        return 0.0
    try:
        return ConvexHull(points).volume
    except QhullError:
        return 0.0


def oracle(v: np.ndarray, sites: np.ndarray) -> np.ndarray:
    """Sibson coordinates of one query by clipping: |V'(v) n V(p_j)| / |V'(v)|."""
    hit = np.flatnonzero((sites == v).all(axis=1))
    if len(hit):
        return np.eye(len(sites))[hit[0]]
    halfspaces = np.column_stack([2.0 * (sites - v), v @ v - (sites**2).sum(axis=1)])
    cell = HalfspaceIntersection(halfspaces, v).intersections
    stolen = np.zeros(len(sites))
    for j, pj in enumerate(sites):
        piece = cell
        for i, pi in enumerate(sites):
            if i != j:
                piece = _clip(piece, 2.0 * (pi - pj), pi @ pi - pj @ pj)
        stolen[j] = _volume(piece)
    return stolen / stolen.sum()


def assert_matches_oracle(queries: np.ndarray, sites: np.ndarray) -> None:
    x = sibson_coordinates(queries, sites).toarray()
    for i, v in enumerate(queries):
        expected = oracle(v, sites)
        np.testing.assert_allclose(x[i], expected, rtol=0, atol=ORACLE_TOL, err_msg=f"query {i}")


# --- point sets ----------------------------------------------------------------------------------


def random_sites(rng: np.random.Generator, n: int, mode: str) -> np.ndarray:
    """n sites in [-1, 1]^3 (generic, mirror-symmetric in x, or on a coarse grid) + box corners."""
    if mode == "mirror":
        half = rng.uniform([0.05, -1, -1], [1, 1, 1], (n // 2 + 1, 3))
        mid = rng.uniform(-1, 1, (2, 3)) * [0, 1, 1]
        pts = np.vstack([half, half * [-1, 1, 1], mid])
    elif mode == "grid":
        pts = np.unique(rng.integers(-2, 3, (n + 4, 3)), axis=0) / 2.0
    else:
        pts = rng.uniform(-1, 1, (n, 3))
    return np.vstack([pts, corners(rng.choice([1.5, 2.0, 3.0]))])


def random_queries(rng: np.random.Generator, m: int, mode: str) -> np.ndarray:
    q = rng.uniform(-1.2, 1.2, (m, 3))
    if mode == "mirror":
        q[: m // 3, 0] = 0.0
    elif mode == "grid":
        q[: m // 3] = np.round(q[: m // 3] * 4) / 4
    return q


def face_layout(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Mirror-symmetric control points on a half-ellipsoid face + the 1.5x box; face queries."""
    axes = np.array([0.8, 1.0, 0.6])

    def surface(u: np.ndarray, w: np.ndarray) -> np.ndarray:
        return np.stack([u, w, np.sqrt(np.clip(1 - u**2 - w**2, 0, None))], axis=1) * axes

    r, phi = 0.85 * np.sqrt(rng.uniform(0, 1, 16)), rng.uniform(-np.pi / 2, np.pi / 2, 16)
    half = surface(np.abs(r * np.cos(phi)) + 0.05, r * np.sin(phi))
    controls = np.vstack([half, half * [-1, 1, 1], surface(np.zeros(8), np.linspace(-0.8, 0.8, 8))])
    box = np.array([0, 0, 0.3]) + np.array([1.2, 1.5, 0.45]) * corners(1.0)
    r, phi = 0.95 * np.sqrt(rng.uniform(0, 1, m)), rng.uniform(0, 2 * np.pi, m)
    u, w = r * np.cos(phi), r * np.sin(phi)
    u[: m // 10] = 0.0
    queries = surface(u, w) + rng.normal(0, 0.01, (m, 3))
    queries[: m // 10, 0] = 0.0
    return queries, np.vstack([controls, box])


def delaunay_power(queries: np.ndarray, sites: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tetrahedra (non-flat) and relative in-sphere margin (r^2 - |v - c|^2) / r^2, (M, T)."""
    tets = Delaunay(sites).simplices
    p = sites[tets]
    e = p[:, 1:] - p[:, :1]
    det6 = np.linalg.det(e)
    lengths = [np.linalg.norm(p[:, i] - p[:, j], axis=1) for i in range(4) for j in range(i)]
    longest = np.max(lengths, axis=0)
    keep = np.abs(det6) >= 1e-10 * longest**3
    tets, p, e = tets[keep], p[keep], e[keep]
    c = p[:, 0] + np.linalg.solve(2 * e, (e**2).sum(axis=2)[..., None])[..., 0]
    r2 = ((p[:, 0] - c) ** 2).sum(axis=1)
    d2 = ((queries[:, None, :] - c[None]) ** 2).sum(axis=2)
    return tets, (r2 - d2) / r2


# --- properties on random point sets -------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(3, 30),
    mode=st.sampled_from(MODES),
)
def test_properties_on_random_sets(seed: int, n: int, mode: str) -> None:
    rng = np.random.default_rng(seed)
    sites = random_sites(rng, n, mode)
    queries = random_queries(rng, 200, mode)
    extent = np.ptp(sites, axis=0).max()
    x = sibson_coordinates(queries, sites)
    dense = x.toarray()
    assert x.shape == (len(queries), len(sites)) and x.dtype == np.float64
    assert dense.min() >= 0.0
    np.testing.assert_allclose(dense.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dense @ sites, queries, rtol=0, atol=1e-9 * extent)

    tets, margin = delaunay_power(queries, sites)
    stored = np.zeros_like(dense, dtype=bool)
    stored[np.repeat(np.arange(len(queries)), np.diff(x.indptr)), x.indices] = True
    for i in range(len(queries)):
        surely = np.unique(tets[margin[i] > 1e-9])
        maybe = np.unique(tets[margin[i] > -1e-9])
        clearly = np.unique(tets[margin[i] > 1e-3])
        assert set(surely) <= set(np.flatnonzero(stored[i])) <= set(maybe)
        assert (dense[i, clearly] > 0).all()


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 30), mode=st.sampled_from(MODES))
def test_lagrange_property_at_and_near_sites(seed: int, n: int, mode: str) -> None:
    rng = np.random.default_rng(seed)
    sites = random_sites(rng, n, mode)
    extent = np.ptp(sites, axis=0).max()
    near = sites + rng.normal(size=sites.shape) * 1e-10 * extent
    for queries in (sites, near):
        x = sibson_coordinates(queries, sites)
        np.testing.assert_array_equal(x.toarray(), np.eye(len(sites)))
        assert x.nnz == len(sites)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), mode=st.sampled_from(MODES))
def test_mask_equals_stored_pattern(seed: int, mode: str) -> None:
    rng = np.random.default_rng(seed)
    sites = random_sites(rng, 15, mode)
    queries = np.vstack([random_queries(rng, 300, mode), sites[:3]])
    x = sibson_coordinates(queries, sites).tocsc()
    for k in range(len(sites)):
        expected = np.zeros(len(queries), dtype=bool)
        expected[x.indices[x.indptr[k] : x.indptr[k + 1]]] = True
        np.testing.assert_array_equal(natural_neighbour_mask(queries, sites, k), expected)


def test_realtime_update_recomputes_only_masked_rows() -> None:
    queries, sites = face_layout(np.random.default_rng(7), 3000)
    before = sibson_coordinates(queries, sites).toarray()
    k = 3
    moved = sites.copy()
    moved[k] += [0.02, -0.01, 0.015]
    after = sibson_coordinates(queries, moved).toarray()
    rows = natural_neighbour_mask(queries, sites, k) | natural_neighbour_mask(queries, moved, k)
    assert 0 < rows.sum() < len(queries)
    np.testing.assert_array_equal(rows, (before[:, k] > 0) | (after[:, k] > 0))
    np.testing.assert_allclose(after[~rows], before[~rows], rtol=0, atol=1e-12)
    patched = before.copy()
    patched[rows] = sibson_coordinates(queries[rows], moved).toarray()
    np.testing.assert_allclose(patched, after, rtol=0, atol=1e-12)


def test_face_layout_precision_and_invariance() -> None:
    queries, sites = face_layout(np.random.default_rng(3), 4000)
    x = sibson_coordinates(queries, sites).toarray()
    np.testing.assert_allclose(x @ sites, queries, rtol=0, atol=1e-12)
    angle = 0.7
    cos, sin = np.cos(angle), np.sin(angle)
    rot = np.array([[cos, -sin, 0], [sin, cos, 0], [0, 0, 1]])
    moved = sibson_coordinates(3.7 * queries @ rot.T + [5, -2, 1], 3.7 * sites @ rot.T + [5, -2, 1])
    np.testing.assert_allclose(moved.toarray(), x, rtol=0, atol=1e-9)


def test_circumsphere_tie_gives_the_same_answer_either_way(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(11)
    sites = np.vstack([rng.uniform(-1, 1, (15, 3)), corners(2.0)])
    tri = Delaunay(sites)
    on_sphere = []
    for tet in sites[tri.simplices]:
        e = tet[1:] - tet[0]
        if abs(np.linalg.det(e)) < 1e-9:
            continue
        c = tet[0] + np.linalg.solve(2 * e, (e**2).sum(axis=1))
        d = rng.normal(size=3)
        v = c + np.linalg.norm(tet[0] - c) * d / np.linalg.norm(d)
        if np.abs(v).max() < 1.9:
            on_sphere.append(v)
    cube = np.vstack([corners(1.0), corners(3.0)])
    cube_q = np.array([[np.sqrt(3), 0, 0], [0, -np.sqrt(3), 0], [np.sqrt(1.5), np.sqrt(1.5), 0]])
    for queries, pts in ((np.array(on_sphere[:40]), sites), (cube_q, cube)):
        monkeypatch.setattr(sibson, "_INSPHERE_TOL", 1e-12)
        without = sibson_coordinates(queries, pts).toarray()
        monkeypatch.setattr(sibson, "_INSPHERE_TOL", -1e-9)
        with_tie = sibson_coordinates(queries, pts).toarray()
        np.testing.assert_allclose(with_tie, without, rtol=0, atol=1e-12)


# --- agreement with the clipping oracle ----------------------------------------------------------


def test_oracle_random() -> None:
    rng = np.random.default_rng(1)
    sites = np.vstack([rng.uniform(-1, 1, (12, 3)), corners(1.5)])
    assert_matches_oracle(rng.uniform(-1.4, 1.4, (12, 3)), sites)


def test_oracle_mirror_symmetric_queries_on_symmetry_plane() -> None:
    rng = np.random.default_rng(2)
    half = rng.uniform([0.1, -1, -1], [1, 1, 1], (6, 3))
    mid = rng.uniform(-1, 1, (3, 3)) * [0, 1, 1]
    sites = np.vstack([half, half * [-1, 1, 1], mid, corners(1.5)])
    queries = rng.uniform(-1, 1, (8, 3)) * [0, 1, 1]
    trapezoid = [(t * half[0] + (1 - t) * half[1]) * [0, 1, 1] for t in (0.3, 0.5, 0.7)]
    assert_matches_oracle(np.vstack([queries, trapezoid]), sites)


def test_oracle_face_layout_midline() -> None:
    queries, sites = face_layout(np.random.default_rng(5), 200)
    assert_matches_oracle(queries[:4], sites)


def test_oracle_cube_corners_and_face_centres() -> None:
    rng = np.random.default_rng(3)
    sites = np.vstack([corners(1.0), np.eye(3), -np.eye(3), corners(2.0)])
    structured = [[0, 0, 0], [0.5, 0, 0], [0.5, 0.5, 0], [0.5, 0.5, 0.5]]
    structured += [[1, 0, 0.3], [1, 1, 0.2], [1.5, 0, 0]]
    queries = rng.uniform(-0.9, 0.9, (6, 3))
    queries[:3, 2] = 0.0
    assert_matches_oracle(np.vstack([structured, queries]), sites)


def test_oracle_points_on_a_sphere() -> None:
    rng = np.random.default_rng(4)
    u = rng.normal(size=(16, 3))
    sites = np.vstack([u / np.linalg.norm(u, axis=1)[:, None], corners(2.0)])
    queries = np.vstack([[0, 0, 0], rng.uniform(-0.6, 0.6, (5, 3)), 1.2 * sites[:3]])
    assert_matches_oracle(queries, sites)


def test_oracle_on_voronoi_features_and_delaunay_simplices() -> None:
    rng = np.random.default_rng(6)
    sites = np.vstack([rng.uniform(-1, 1, (10, 3)), corners(1.5)])
    vor = Voronoi(sites)
    faces = [r for r in vor.ridge_vertices if -1 not in r]
    on_face = [vor.vertices[r].mean(axis=0) for r in faces[:4]]
    tri = Delaunay(sites)
    on_vertex = [v for v in vor.vertices if np.abs(v).max() < 1.4][:2]
    edge = sites[tri.simplices[0, :2]].mean(axis=0)
    facet = sites[tri.simplices[1, :3]].mean(axis=0)
    queries = np.array(on_face + on_vertex + [edge, facet])
    assert_matches_oracle(queries[np.abs(queries).max(axis=1) < 1.45], sites)


def test_oracle_on_and_near_a_site() -> None:
    rng = np.random.default_rng(8)
    sites = np.vstack([rng.uniform(-1, 1, (10, 3)), corners(1.5)])
    directions = rng.normal(size=(3, 3))
    near = sites[:3] + 1e-6 * directions / np.linalg.norm(directions, axis=1)[:, None]
    assert_matches_oracle(np.vstack([sites[3:5], near]), sites)


# --- errors --------------------------------------------------------------------------------------


def test_query_outside_hull_names_first_offender() -> None:
    sites = np.vstack([np.random.default_rng(0).uniform(-1, 1, (6, 3)), corners(1.5)])
    queries = np.array([[0, 0, 0], [0.1, 0.2, 0.3], [2.0, 0, 0], [0, 1.5, 0], [0, 0, 5.0]])
    with pytest.raises(SibsonError, match=r"3 of 5 queries .*index 2, point \[2\.0, 0\.0, 0\.0\]"):
        sibson_coordinates(queries, sites)
    on_hull = queries[[0, 3]]
    with pytest.raises(SibsonError, match=r"1 of 2 queries .*index 1"):
        sibson_coordinates(on_hull, sites)
    with pytest.raises(SibsonError, match="index 1"):
        natural_neighbour_mask(on_hull, sites, 0)


def test_duplicate_sites_named() -> None:
    sites = np.vstack([np.random.default_rng(0).uniform(-1, 1, (6, 3)), corners(1.5)])
    sites = np.vstack([sites, sites[4]])
    with pytest.raises(SibsonError, match=r"duplicate sites.*4 and 14"):
        sibson_coordinates(np.zeros((1, 3)), sites)


FLAT_SITES = corners(1.0) * [1, 1, 0] + np.arange(8)[:, None] * [0.01, 0, 0]


@pytest.mark.parametrize(
    ("queries", "sites", "message"),
    [
        (np.zeros((1, 3)), corners(1.0)[:4], "at least 5 sites"),
        (np.zeros((1, 3)), FLAT_SITES, "coplanar"),
        (np.zeros((1, 3)), corners(1.0)[:, :2], r"sites must have shape \(n, 3\)"),
        (np.zeros(3), corners(1.0), r"queries must have shape \(n, 3\)"),
        (np.array([[0.0, np.nan, 0.0]]), corners(1.0), "queries contain non-finite.*index 0"),
        (np.zeros((1, 3)), np.vstack([corners(1.0), [np.inf, 0, 0]]), "sites contain .*index 8"),
    ],
)
def test_invalid_input(queries: np.ndarray, sites: np.ndarray, message: str) -> None:
    with pytest.raises(SibsonError, match=message):
        sibson_coordinates(queries, sites)


def test_mask_rejects_bad_site_index() -> None:
    with pytest.raises(SibsonError, match="k=8"):
        natural_neighbour_mask(np.zeros((1, 3)), corners(1.0), 8)


def test_empty_queries() -> None:
    x = sibson_coordinates(np.zeros((0, 3)), corners(1.0))
    assert x.shape == (0, 8) and x.nnz == 0


def test_mask_of_several_sites_is_the_union_of_their_masks():
    rng = np.random.default_rng(3)
    sites = np.vstack([rng.uniform(-1, 1, (12, 3)), corners(2.0)])
    queries = rng.uniform(-0.9, 0.9, (300, 3))
    union = natural_neighbour_mask(queries, sites, np.array([2, 5, 7]))
    each = [natural_neighbour_mask(queries, sites, k) for k in (2, 5, 7)]
    np.testing.assert_array_equal(union, each[0] | each[1] | each[2])
