"""Waters muscles: the displacement law by hand, folding at large contraction, symmetry, placement, JSON."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import LinearNDInterpolator

from puppet.face.muscles import (
    LinearMuscle,
    Sphincter,
    default_muscles,
    flat_grid,
    mirror_muscle,
    muscles_from_json,
    muscles_to_json,
    place,
    place_coefficients,
)
from puppet.runtime.musclesolver import (
    EdgeConstraints,
    MuscleModel,
    control_point_displacements,
    folded_triangles,
    repelled_travel,
)

AXIS_MUSCLE = LinearMuscle("m", np.zeros(3), np.array([1.0, 0, 0]), alpha=30.0, r_e=1.0, r_f=2.0, pull=0.1)


GRID = flat_grid()
GRID_MUSCLE = LinearMuscle("g", np.array([-0.25, 0, 0]), np.array([0.25, 0, 0]), 30.0, 0.5, 0.75, 0.075)


def displacement_at(points: np.ndarray, muscle: LinearMuscle, c: float) -> np.ndarray:
    """Classic displacements of loose points (a mesh of degenerate triangles: no edge constraints needed)."""
    return MuscleModel(points, np.zeros((0, 3), int), [muscle]).displace({muscle.name: c})


def test_axis_point_inside_r_e_moves_by_sine_fall_off():
    d = displacement_at(np.array([[0.5, 0, 0]]), AXIS_MUSCLE, 2.0)
    np.testing.assert_allclose(d, [[-2.0 * 0.1 * np.sin(np.pi / 4), 0, 0]])


def test_axis_point_between_r_e_and_r_f_moves_by_cosine_fall_off():
    d = displacement_at(np.array([[1.5, 0, 0]]), AXIS_MUSCLE, 1.0)
    np.testing.assert_allclose(d, [[-0.1 * np.cos(np.pi / 4), 0, 0]])


def test_off_axis_point_falls_off_with_angle_and_moves_toward_the_fixed_end():
    mu = np.radians(15.0)
    p = 0.5 * np.array([np.cos(mu), np.sin(mu), 0])
    d = displacement_at(p[None], AXIS_MUSCLE, 1.0)
    expected = 0.1 * np.cos(np.pi / 4) * np.sin(np.pi / 4) * -p / 0.5
    np.testing.assert_allclose(d[0], expected)


@pytest.mark.parametrize("point", [[0.5 * np.cos(0.7), 0.5 * np.sin(0.7), 0], [2.5, 0, 0], [-0.5, 0, 0], [0, 0, 0]])
def test_points_outside_the_zone_stay(point):
    np.testing.assert_array_equal(displacement_at(np.array([point], float), AXIS_MUSCLE, 10.0), 0.0)


def test_sphincter_pulls_toward_its_centre_in_the_frontal_plane():
    s = Sphincter("s", np.zeros(3), np.array([2.0, 1.0, 1.0]), squeeze=0.3)
    points = np.array([[1.0, 0, 0.2], [0, 0.5, 0], [2.5, 0, 0]])
    d = control_point_displacements([s], {"s": 1.0}, points)
    q = np.sqrt(0.25 + 0.04)
    np.testing.assert_allclose(d[0], [-0.3 * np.cos(np.pi / 2 * q) ** 2, 0, 0])
    np.testing.assert_allclose(d[1], [0, -0.3 * 0.5 * np.cos(np.pi / 4) ** 2, 0])
    np.testing.assert_array_equal(d[2], 0.0)


def test_repulsive_law_keeps_ordinary_travel_and_never_reaches_the_bone():
    dist = np.full(5, 1.0)
    travel = np.array([0.1, 0.5, 0.5 + 1e-9, 2.0, 1e6])
    out = repelled_travel(travel, dist)
    np.testing.assert_allclose(out[:3], [0.1, 0.5, 0.5])
    assert np.all(out < dist)
    np.testing.assert_allclose(out[3], 1.0 - 1.0 / 8.0)


def test_improved_equals_classic_at_ordinary_contraction():
    v, t = GRID
    classic = MuscleModel(v, t, [GRID_MUSCLE], "classic").displace({"g": 1.0})
    improved = MuscleModel(v, t, [GRID_MUSCLE], "improved").displace({"g": 1.0})
    np.testing.assert_allclose(improved, classic)


def test_classic_folds_at_contraction_10_and_improved_does_not():
    v, t = GRID
    classic = MuscleModel(v, t, [GRID_MUSCLE], "classic").displace({"g": 10.0})
    improved = MuscleModel(v, t, [GRID_MUSCLE], "improved").displace({"g": 10.0})
    assert folded_triangles(v, v + classic, t).sum() > 0
    assert folded_triangles(v, v + improved, t).sum() == 0
    assert np.all(np.linalg.norm(improved, axis=1) < np.linalg.norm(v - GRID_MUSCLE.fixed, axis=1) + 1e-12)


def test_control_points_spread_then_edge_constraints_do_not_fold_at_10():
    v, t = GRID
    coarse = np.arange(41) % 5 == 0
    control = np.flatnonzero(np.logical_and.outer(coarse, coarse).ravel())
    d = control_point_displacements([GRID_MUSCLE], {"g": 10.0}, v[control])
    spread = LinearNDInterpolator(v[control, :2], d)(v[:, :2])
    EdgeConstraints(v, t).relax(spread)
    assert folded_triangles(v, v + spread, t).sum() == 0


def test_default_face_zygomatic_major_folds_only_in_classic_mode(face):
    muscles = default_muscles(face)
    skin = face.parts["skin"]
    mask = np.zeros(len(face.vertices), bool)
    mask[skin] = True
    tri = face.triangles[mask[face.triangles].all(axis=1)]
    for mode, folds in (("classic", True), ("improved", False)):
        d = MuscleModel(face.vertices, face.triangles, muscles, mode, movable=skin).displace({"zygomatic_major_l": 10})
        assert (folded_triangles(face.vertices, face.vertices + d, tri).sum() > 0) == folds, mode
        assert np.all(d[~mask] == 0)


@pytest.mark.parametrize("mode", ["classic", "improved"])
def test_mirrored_muscle_on_mirrored_mesh_moves_mirrored(mode):
    v, t = GRID
    muscle = LinearMuscle("m_l", np.array([0.3, -0.1, 0]), np.array([-0.15, 0.1, 0]), 25.0, 0.45, 0.7, 0.07)
    flip = np.array([-1.0, 1, 1])
    mirrored_v, mirrored_t = v * flip, t[:, ::-1]
    d = MuscleModel(v, t, [muscle], mode).displace({"m_l": 8.0})
    dm = MuscleModel(mirrored_v, mirrored_t, [mirror_muscle(muscle, "m_r")], mode).displace({"m_r": 8.0})
    np.testing.assert_allclose(dm, d * flip, atol=1e-12)


def test_default_muscles_are_18_paired_linear_muscles_and_three_sphincters(face):
    muscles = default_muscles(face)
    linear = {m.name: m for m in muscles if isinstance(m, LinearMuscle)}
    sphincters = {m.name for m in muscles if isinstance(m, Sphincter)}
    assert len(linear) == 18 and len(muscles) == len({m.name for m in muscles})
    assert sphincters == {"orbicularis_oris", "orbicularis_oculi_l", "orbicularis_oculi_r"}
    left = {n[:-2] for n in linear if n.endswith("_l")}
    assert left == {n[:-2] for n in linear if n.endswith("_r")} and len(left) == 9
    for base in left:  # the default face is symmetric, so each right muscle mirrors its left one
        l, r = linear[base + "_l"], linear[base + "_r"]
        np.testing.assert_allclose(r.fixed, l.fixed * [-1, 1, 1], atol=1e-6)
        np.testing.assert_allclose(r.insertion, l.insertion * [-1, 1, 1], atol=1e-6)
        assert l.fixed[0] > 0 and 0 < l.r_e < l.r_f and l.pull > 0
    skin = face.vertices[face.parts["skin"]]
    ends = np.array([e for m in linear.values() for e in (m.fixed, m.insertion)])
    assert np.min(np.linalg.norm(ends[:, None] - skin[None], axis=2), axis=1).max() == 0.0


def test_zygomatic_major_pulls_the_mouth_corner_up_and_out(face):
    muscles = default_muscles(face)
    corner = face.feature_vertices["8.3"]
    d = MuscleModel(face.vertices, face.triangles, muscles).displace({"zygomatic_major_l": 1.0})
    assert d[corner, 0] > 0 and d[corner, 1] > 0
    assert np.all(d[face.feature_vertices["8.4"]] == 0)


def test_placement_round_trips_and_follows_a_similarity_transform():
    rng = np.random.default_rng(1)
    fp = {"a": rng.normal(size=3), "b": rng.normal(size=3), "c": rng.normal(size=3)}
    point = rng.normal(size=3)
    coef = place_coefficients(point, fp, ["a", "b", "c"])
    np.testing.assert_allclose(place(fp, ["a", "b", "c"], coef), point)
    angle = 0.4
    rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    moved = {k: 2.5 * rot @ p + [1, 2, 3] for k, p in fp.items()}
    np.testing.assert_allclose(place(moved, ["a", "b", "c"], coef), 2.5 * rot @ point + [1, 2, 3])


def test_json_round_trip(face):
    muscles = default_muscles(face)
    back = muscles_from_json(json.loads(json.dumps(muscles_to_json(muscles))))
    assert muscles_to_json(back) == muscles_to_json(muscles)
    assert [type(m) for m in back] == [type(m) for m in muscles]


def test_bad_json_names_the_muscle():
    entry = muscles_to_json([AXIS_MUSCLE])[0] | {"r_f": 0.5}
    with pytest.raises(ValueError, match="muscle #0 \\(m\\)"):
        muscles_from_json([entry])


def test_unknown_muscle_is_an_error():
    with pytest.raises(KeyError, match="unknown muscle"):
        MuscleModel(*GRID, [GRID_MUSCLE]).displace({"nope": 1.0})


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.15), st.lists(st.floats(0.0, 0.02), min_size=2, max_size=8))
def test_edge_constraints_check_exactly_whatever_fields_came_before(seed, bend, wobbles):
    """The check keeps a reference field and skips the triangles that cannot have reached their
    floor since: over any sequence of fields (one bend of the grid, wobbled a little or a lot) it
    finds exactly the squeezed corners an exact check of every triangle finds, and fixes each
    field as a fresh instance (no history) does."""
    v, t = GRID
    rng = np.random.default_rng(seed)
    kept = EdgeConstraints(v, t)
    base = bend * np.sin(8 * v[:, [1, 0, 2]] + rng.uniform(0, 6, 3))
    for wobble in wobbles:
        field = base + wobble * rng.normal(size=(len(v), 3))
        field[:, 2] = 0.0
        squeezed = EdgeConstraints(v, t).squeezed(v + field)
        fixed, fresh = field.copy(), field.copy()
        assert kept.relax(fixed) == squeezed
        EdgeConstraints(v, t).relax(fresh)
        np.testing.assert_array_equal(fixed, fresh)
        assert folded_triangles(v, v + fixed, t).sum() == 0
