"""Weighted DFFD of one region, on a small curved sheet of skin."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.runtime.dffd import DffdError, RegionDeformer, weighted_coefficients
from puppet.runtime.sibson import sibson_coordinates
from puppet.runtime.spreading import catmull_rom_weights, lip_line_weights


def _sheet(n: int = 15) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    return np.c_[u.ravel(), v.ravel(), 0.3 * np.cos(u.ravel()) * np.cos(v.ravel())]


def _deformer(weights=None) -> tuple[RegionDeformer, np.ndarray, np.ndarray]:
    vertices = _sheet()
    sites = vertices[[0, 14, 112, 210, 224, 56, 168]]
    sites = np.vstack([sites, [[0.0, 0.0, -0.4]]])
    w = np.ones(len(sites)) if weights is None else weights
    return RegionDeformer("sheet", vertices, sites, w), vertices, sites


def test_coefficients_are_a_partition_of_unity_over_the_real_points():
    deformer, vertices, _ = _deformer()
    c = deformer.coefficients
    assert c.shape == (len(vertices), 8)
    np.testing.assert_allclose(np.asarray(c.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert c.min() >= 0


@settings(max_examples=25, deadline=None)
@given(st.tuples(*[st.floats(-0.2, 0.2)] * 3))
def test_translating_every_control_point_translates_the_region(move):
    deformer, vertices, sites = _deformer(np.array([1, 2, 0.5, 1, 1, 3, 1, 0.5]))
    d = np.broadcast_to(np.array(move), sites.shape)
    np.testing.assert_allclose(deformer.coefficients @ d, np.broadcast_to(move, vertices.shape), atol=1e-12)


def test_a_direct_point_moves_its_vertex_exactly_and_weights_shape_the_rest():
    light, vertices, sites = _deformer()
    heavy, _, _ = _deformer(np.array([1, 1, 1, 1, 1, 1, 1, 1.0]) + np.eye(8)[5] * 4)
    d = np.zeros_like(sites)
    d[5] = (0, 0, 0.1)
    for deformer in (light, heavy):
        np.testing.assert_allclose((deformer.coefficients @ d)[56], d[5], atol=1e-15)
    spread_light = np.abs(light.coefficients @ d).sum()
    spread_heavy = np.abs(heavy.coefficients @ d).sum()
    assert spread_heavy > spread_light


def test_unweighted_coefficients_equal_sibson_without_the_box_share():
    deformer, vertices, sites = _deformer()
    x = sibson_coordinates(vertices, np.vstack([sites, deformer.box])).toarray()[:, :8]
    np.testing.assert_allclose(deformer.coefficients.toarray(), x / x.sum(axis=1, keepdims=True), atol=1e-12)


def test_rebase_recomputes_only_affected_rows_and_matches_a_fresh_computation():
    deformer, vertices, sites = _deformer()
    moved = sites.copy()
    moved[5] += (0.05, 0.05, 0.1)
    queries = vertices + deformer.coefficients @ (moved - sites)
    redone = deformer.rebase(queries, moved)
    assert 0 < len(redone) < len(vertices)
    fresh = sibson_coordinates(queries, np.vstack([moved, deformer.box]))
    np.testing.assert_allclose(deformer.sibson.toarray(), fresh.toarray(), atol=1e-12)


def test_a_query_seeing_only_box_corners_is_a_clear_error():
    sibson = sp.csr_matrix(np.array([[0.5, 0.5, 0, 0], [0, 0, 0.3, 0.7]]))
    with pytest.raises(DffdError, match="region 'lips'.*first row 1"):
        weighted_coefficients(sibson, np.ones(2), "lips")


def test_catmull_rom_interpolates_its_keys_and_keeps_unity():
    for u in np.linspace(0, 1, 11):
        assert catmull_rom_weights(u).sum() == pytest.approx(1.0)
    np.testing.assert_allclose(catmull_rom_weights(0.0), [0, 1, 0, 0])
    np.testing.assert_allclose(catmull_rom_weights(1.0), [0, 0, 1, 0])
    keys = np.array([[0, 0, 0], [1, 0.5, 0], [2, 0.6, 0], [3, 0, 0.0]])
    weights = lip_line_weights(keys, np.array([1.5, 0.55, 0.0]))
    assert sum(weights.values()) == pytest.approx(1.0)
    assert max(weights, key=weights.get) in (1, 2)


def test_rebase_rebuilds_the_box_when_the_skin_nears_its_walls():
    deformer, vertices, sites = _deformer()
    moved = sites + (0.0, 0.0, 1.5)
    queries = vertices + deformer.coefficients @ (moved - sites)
    redone = deformer.rebase(queries, moved)
    assert len(redone) == len(vertices)
    fresh = sibson_coordinates(queries, np.vstack([moved, deformer.box]))
    np.testing.assert_allclose(deformer.sibson.toarray(), fresh.toarray(), atol=1e-12)
    assert deformer.box[:, 2].min() > sites[:, 2].max() - 1.0
