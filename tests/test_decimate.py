"""Decimation for levels of detail: fewer triangles over the same vertices, the same surface."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.face.decimate import decimate


def _edges(triangles: np.ndarray) -> np.ndarray:
    return np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)


def _edge_counts(triangles: np.ndarray) -> dict[tuple[int, int], int]:
    pairs, counts = np.unique(_edges(triangles), axis=0, return_counts=True)
    return {tuple(p): int(c) for p, c in zip(pairs.tolist(), counts)}


def _sphere(subdivisions: int, offset: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A unit icosphere whose vertices sit ``offset`` rows into a larger array (as a face's part does)."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    vertices = np.vstack([np.zeros((offset, 3)), sphere.vertices])
    return vertices, np.asarray(sphere.faces) + offset


@settings(max_examples=12, deadline=None)
@given(subdivisions=st.sampled_from([2, 3]), keep=st.floats(0.15, 0.9), offset=st.integers(0, 50))
def test_a_closed_surface_stays_closed_oriented_and_on_its_shape(subdivisions, keep, offset):
    vertices, triangles = _sphere(subdivisions, offset)
    coarse = decimate(vertices, triangles, keep)
    assert coarse.dtype == np.int32
    assert len(coarse) < len(triangles)
    assert set(np.unique(coarse)) <= set(np.unique(triangles))  # the same vertices, none made
    assert np.all((coarse[:, 0] != coarse[:, 1]) & (coarse[:, 1] != coarse[:, 2]) & (coarse[:, 2] != coarse[:, 0]))
    assert len(np.unique(np.sort(coarse, axis=1), axis=0)) == len(coarse)
    assert set(_edge_counts(coarse).values()) == {2}  # closed and manifold
    used = len(np.unique(coarse))
    assert used - len(_edge_counts(coarse)) + len(coarse) == 2  # still a sphere (Euler characteristic)
    a, b, c = (vertices[coarse[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    centres = (a + b + c) / 3
    assert np.all(np.einsum("ij,ij->i", normals, centres) > 0)  # every triangle still faces out
    assert np.linalg.norm(centres, axis=1).min() > 0.7  # and lies near the sphere (an icosahedron's: 0.79)


def test_a_quarter_is_reached_on_a_smooth_surface():
    vertices, triangles = _sphere(4)
    coarse = decimate(vertices, triangles, 0.25)
    assert len(coarse) <= 0.26 * len(triangles)


def test_an_open_border_is_kept_exactly():
    vertices, triangles = _sphere(3)
    centres = vertices[triangles].mean(axis=1)
    cup = triangles[centres[:, 2] > 0.1]
    border = {e for e, n in _edge_counts(cup).items() if n == 1}
    coarse = decimate(vertices, cup, 0.25)
    assert len(coarse) < 0.5 * len(cup)
    assert {e for e, n in _edge_counts(coarse).items() if n == 1} == border


def test_where_one_colour_meets_another_stays_where_it_was():
    vertices, triangles = _sphere(3)
    colors = np.where(vertices[:, 2:3] > 0.6, [[0.1, 0.05, 0.02]], [[0.9, 0.9, 0.85]])
    coarse = decimate(vertices, triangles, 0.25, colors=colors)
    dark = vertices[:, 2] > 0.6
    edges = _edges(triangles)
    meets = np.unique(edges[dark[edges[:, 0]] != dark[edges[:, 1]]])
    assert set(meets) <= set(np.unique(coarse))  # every vertex on the border is still drawn
    mixed = lambda t: dark[t].any(axis=1) & ~dark[t].all(axis=1)  # noqa: E731 - triangles holding both colours
    area = lambda t: np.linalg.norm(np.cross(vertices[t[:, 1]] - vertices[t[:, 0]],  # noqa: E731
                                             vertices[t[:, 2]] - vertices[t[:, 0]]), axis=1)
    assert area(coarse[mixed(coarse)]).sum() == pytest.approx(area(triangles[mixed(triangles)]).sum(), rel=0.25)
    assert len(coarse) < 0.6 * len(triangles)


def test_a_small_closed_part_never_collapses_past_a_closed_surface():
    box = trimesh.creation.box()
    coarse = decimate(box.vertices, box.faces, 0.01)
    assert set(_edge_counts(coarse).values()) == {2}
    assert len(coarse) >= 4


def test_the_coarse_surface_stays_within_a_fraction_of_an_edge_of_the_fine_one():
    n = 31
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    vertices = np.stack([x.ravel(), y.ravel(), 0.03 * np.sin(25 * x.ravel()) * np.sin(21 * y.ravel())], axis=1)
    k = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    triangles = np.concatenate([np.stack([k, k + 1, k + n + 1], 1), np.stack([k, k + n + 1, k + n], 1)])
    coarse = decimate(vertices, triangles, 0.05)
    assert len(coarse) < 0.5 * len(triangles)
    a, b, c = (vertices[coarse[:, i], :2] for i in range(3))  # a height field: find each point's coarse triangle
    p = vertices[:, None, :2]
    det = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    s = ((p - a)[..., 0] * (c - a)[:, 1] - (p - a)[..., 1] * (c - a)[:, 0]) / det
    t = ((b - a)[:, 0] * (p - a)[..., 1] - (b - a)[:, 1] * (p - a)[..., 0]) / det
    inside = (s >= -1e-9) & (t >= -1e-9) & (s + t <= 1 + 1e-9)
    assert inside.any(axis=1).all()
    which = inside.argmax(axis=1)
    rows = np.arange(len(vertices))
    height = ((1 - s - t)[rows, which] * vertices[coarse[which, 0], 2] + s[rows, which] * vertices[coarse[which, 1], 2]
              + t[rows, which] * vertices[coarse[which, 2], 2])
    assert np.abs(height - vertices[:, 2]).max() < 0.5 / (n - 1)  # half the fine mesh's edge
