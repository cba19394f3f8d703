"""MPEG-4 FAPs move the default face as the standard means them, and are measured back exactly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.face.rigid import IDENTITY
from puppet.fap.table import UnknownFapError, faps
from puppet.runtime.fapengine import FapEngine


def _translational(runtime) -> list:
    effects = runtime.faps.effects()
    return [f for f in faps() if effects[f.number].startswith("moves control point")]


def _allowed_regions(rig, point: str) -> set[str]:
    """Regions that list the point, and every region their passive points carry motion into."""
    allowed = {r.name for r in rig.regions if point in r.control_points}
    grew = True
    while grew:
        driven = {r.name for r in rig.regions
                  if any(rig.point(c).role == "passive" and rig.point(c).driver in allowed for c in r.control_points)}
        grew = not driven <= allowed
        allowed |= driven
    return allowed


def test_every_translational_fap_moves_its_point_by_value_times_fapu_along_its_direction(runtime, face):
    fapu = face.fapu
    checked = 0
    low, high = runtime.faps.reach
    capped = []
    for f in _translational(runtime):
        values = np.zeros(68)
        values[f.number - 1] = 150.0
        value = runtime.faps.shown(values)[f.number - 1]  # up to the face's reach (puppet.runtime.foldlimits),
        if value < 150:  # the cheeks' to their crease limit (puppet.runtime.creaselimit)
            assert value == min(150.0, high[f.number - 1]) or f.number in (41, 42), f"FAP {f.number} {f.name}"
            capped.append(f.number)
        moved = runtime.deform_faps(values)
        for point in f.feature_points:
            vertex = face.feature_vertices[point]
            assert (moved[vertex] - face.vertices[vertex]) @ f.axis == pytest.approx(value * fapu[f.unit], abs=1e-9), \
                f"FAP {f.number} {f.name}"  # across its axis, the calibration may move it (fapcalibration)
        checked += 1
    assert checked == 39  # 4-13, 16-18, 31-42, 51-64
    # squeezing the brows, flaring the nostrils: a few mm is all they do; stretching the lip corners
    # (inner and outer) past 145 MW, 7.6 mm on the default face; lifting the cheeks past their crease
    assert len(capped) <= 10, capped


@pytest.mark.slow
def test_every_translational_fap_moves_no_vertex_outside_its_regions(runtime, face):
    owner = np.empty(len(face.vertices), dtype=object)
    for region in runtime.rig.regions:
        owner[region.vertices] = region.name
    for f in _translational(runtime):
        moved = np.linalg.norm(runtime.deform_faps({f.name: 200}) - face.vertices, axis=1) > 1e-12
        allowed = set().union(*(_allowed_regions(runtime.rig, p) for p in f.feature_points))
        outside = set(owner[moved]) - allowed
        assert not outside, f"FAP {f.number} {f.name} moved {outside}"


def test_open_jaw_drops_the_chin_by_value_times_mns_and_opens_the_mouth(runtime, face):
    moved = runtime.deform_faps({"open_jaw": 400})
    chin, lip_top, lip_bottom = (face.feature_vertices[p] for p in ("2.1", "2.2", "2.3"))
    assert face.vertices[chin, 1] - moved[chin, 1] == pytest.approx(400 * face.fapu["MNS0"], rel=1e-9)
    assert moved[lip_top, 1] - moved[lip_bottom, 1] > 300 * face.fapu["MNS0"]
    thrust = runtime.deform_faps({"thrust_jaw": 100, "shift_jaw": 50})
    np.testing.assert_allclose(thrust[chin] - face.vertices[chin],
                               [-50 * face.fapu["MW0"], 0, 100 * face.fapu["MNS0"]], atol=1e-12)


@pytest.mark.parametrize("number, point, sign", [(19, "3.1", -1), (20, "3.2", -1), (21, "3.3", 1), (22, "3.4", 1)])
def test_eyelids_move_their_centre_point_by_value_times_irisd_on_the_eyeball(runtime, face, number, point, sign):
    moved = runtime.deform_faps({number: 300})
    vertex = face.feature_vertices[point]
    assert moved[vertex, 1] - face.vertices[vertex, 1] == pytest.approx(sign * 300 * face.fapu["IRISD0"], rel=1e-9)
    centre = face.pivots["eye_l" if point in ("3.1", "3.3") else "eye_r"]
    assert np.linalg.norm(moved[vertex] - centre) == pytest.approx(np.linalg.norm(face.vertices[vertex] - centre))


def test_eyeballs_turn_left_and_down_for_positive_values(runtime, face):
    au = face.fapu["AU"]
    for name, pupil, eye in (("l", "3.5", "eye_l"), ("r", "3.6", "eye_r")):
        p = face.feature_vertices[pupil]
        centre = face.pivots[eye]
        left = runtime.deform_faps({f"yaw_{name}_eyeball": 20000})[p] - centre
        down = runtime.deform_faps({f"pitch_{name}_eyeball": 20000})[p] - centre
        assert np.arctan2(left[0], left[2]) == pytest.approx(20000 * au, rel=1e-9)
        assert np.arctan2(-down[1], down[2]) == pytest.approx(20000 * au, rel=1e-9)


def test_the_eyes_turn_past_where_the_lids_stop_following_and_stop_at_50_degrees(runtime, face):
    """A gaze FAP's reach caps the lid skin it carries (``skin_reach``), not the eyeball: looking
    further down turns the eye on and folds nothing more; past 50 degrees the eye stops."""
    from puppet.runtime.musclesolver import folded_triangles

    au, pitch = face.fapu["AU"], 25
    lids_stop = runtime.faps.skin_reach[1, pitch - 1]
    assert 0 < lids_stop * au < np.radians(40)
    p, centre = face.feature_vertices["3.5"], face.pivots["eye_l"]

    def down(value):
        moved = runtime.deform_faps({pitch: value})
        folds = folded_triangles(face.vertices, moved, np.asarray(face.triangles)).sum()
        offset = moved[p] - centre
        return np.arctan2(-offset[1], offset[2]), folds

    at_stop, folds_at_stop = down(lids_stop)
    further, folds_further = down(np.radians(40) / au)
    assert at_stop == pytest.approx(lids_stop * au, rel=1e-9)
    assert further == pytest.approx(np.radians(40), rel=1e-9)
    assert folds_further <= folds_at_stop
    assert down(np.radians(80) / au)[0] == pytest.approx(np.radians(50), rel=1e-9)


def test_head_pitch_yaw_roll_turn_about_7_1(runtime, face):
    nose = face.feature_vertices["9.3"]
    top = face.feature_vertices["11.4"]
    assert runtime.deform_faps({"head_pitch": 20000})[nose, 1] < face.vertices[nose, 1]
    assert runtime.deform_faps({"head_yaw": 20000})[nose, 0] > face.vertices[nose, 0]
    assert runtime.deform_faps({"head_roll": 20000})[top, 0] < face.vertices[top, 0]
    skull = runtime.rig.region("upper_teeth").vertices
    turned = runtime.deform_faps({"head_pitch": 15000, "head_yaw": -10000, "head_roll": 8000})
    centre = face.feature_points["7.1"]
    np.testing.assert_allclose(np.linalg.norm(turned[skull] - centre, axis=1),
                               np.linalg.norm(face.vertices[skull] - centre, axis=1), atol=1e-9)
    assert np.abs(turned[skull] - face.vertices[skull]).max() > 0.05


def test_high_level_faps_are_not_values_and_selects_must_exist(runtime):
    with pytest.raises(ValueError, match="pass it as viseme="):
        runtime.deform_faps({"viseme": 10})
    with pytest.raises(ValueError, match="visemes are numbered 0 to 14"):
        runtime.deform_faps(viseme=(15, 0, 63))
    with pytest.raises(ValueError, match="expressions are numbered 0 to 6"):
        runtime.deform_faps(expression=(7, 63, 0, 0))
    values = np.zeros(68)
    values[0] = 10
    with pytest.raises(ValueError, match="FAP 1 and 2 are not values"):
        runtime.deform_faps(values)


def test_p_b_m_closes_the_lips_even_while_smiling(runtime, face):
    top, bottom = face.feature_vertices["2.2"], face.feature_vertices["2.3"]
    for expression in (None, (1, 63, 0, 0)):
        lips = runtime.deform_faps(viseme=(1, 0, 63), expression=expression)
        gap = (lips[top, 1] - lips[bottom, 1]) / face.fapu["MNS0"]
        assert -8 < gap < 8, f"p/b/m with {expression}: lips {gap:.0f} MNS apart"


def test_faps_that_do_nothing_on_the_default_face_say_why(runtime):
    effects = runtime.faps.effects()
    nothing = {n for n, what in effects.items() if what.startswith("nothing")}
    assert nothing == {29, 30, 47, 65, 66, 67, 68}
    for n in nothing:
        assert np.array_equal(runtime.deform_faps({n: 300}), runtime.deform_faps({}))


def test_unknown_fap_names_suggest_the_closest(runtime):
    with pytest.raises(UnknownFapError, match="did you mean 'open_jaw'"):
        runtime.deform_faps({"opn_jaw": 100})
    with pytest.raises(UnknownFapError, match="numbered 1 to 68"):
        runtime.deform_faps({69: 1})


def test_visemes_and_expressions_blend_and_add_to_low_level_faps(runtime):
    engine = runtime.faps
    a = engine.low_level(np.zeros(68), viseme=(10, 0, 63))
    half = engine.low_level(np.zeros(68), viseme=(10, 14, 32))
    u = engine.low_level(np.zeros(68), viseme=(14, 0, 63))
    np.testing.assert_allclose(half, a * 32 / 63 + u * 31 / 63)
    joy = engine.low_level(np.zeros(68), expression=(1, 63, 0, 0))
    low = np.full(68, 5.0)
    low[:2] = 0
    both = engine.low_level(low, viseme=(10, 0, 63), expression=(1, 63, 0, 0))
    np.testing.assert_allclose(both, low + a + joy)


def test_encoding_a_decoded_frame_gives_the_frame_back(runtime, face):
    rng = np.random.default_rng(5)
    effects = runtime.faps.effects()
    x = np.zeros(68)
    for f in faps():
        if f.number > 2 and not effects[f.number].startswith("nothing") and f.number != 46:
            x[f.number - 1] = rng.uniform(-200, 200) if f.bidirectional else rng.uniform(0, 300)
    x[[47, 48, 49]] = rng.uniform(-15000, 15000, 3)
    encoded = runtime.faps.encode(runtime.deform_faps(x))
    np.testing.assert_allclose(encoded, runtime.faps.shown(x), atol=1e-6)  # what the face shows
    low, high = runtime.faps.reach
    within = np.clip(x, 0.9 * low, 0.9 * high)
    for (inner, outer) in runtime.rig.fap_follow:
        within[outer - 1] = within[inner - 1] = min(within[inner - 1], within[outer - 1], key=abs)
    within[[40, 41]] = runtime.faps.shown(within)[[40, 41]]  # lift_cheek within the cheeks' crease limit
    np.testing.assert_array_equal(runtime.faps.shown(within), within)  # within its limits, the frame itself
    np.testing.assert_allclose(runtime.faps.encode(runtime.deform_faps(within)), within, atol=1e-6)


def _sane(runtime, face, vertices, times=2) -> bool:
    """Finite, and no vertex further from the head's pivot than ``times`` the farthest rest vertex."""
    pivot = runtime.rig.rigid_parts["head"].pivot
    reach = np.linalg.norm(face.vertices - pivot, axis=1).max()
    return bool(np.isfinite(vertices).all() and (np.linalg.norm(vertices - pivot, axis=1) <= times * reach).all())


@pytest.mark.parametrize("value", [1e20, -1e20, 1e300, -1e300, 56298.0])
def test_an_extreme_value_of_any_fap_poses_a_finite_sane_face(runtime, face, value):
    for number in range(3, 69):
        values = np.zeros(68)
        values[number - 1] = value
        given = values.copy()
        assert _sane(runtime, face, runtime.deform_faps(values)), f"FAP {number} = {value:g}"
        assert np.array_equal(values, given)  # the caller's values are never changed
    assert _sane(runtime, face, runtime.deform_faps(np.full(68, value) * (np.arange(68) > 1)), times=3)  # all at once


def test_the_jaw_stops_at_the_solvers_reach_and_the_skin_with_it(runtime, face):
    reach = runtime.faps.reach[1, 2]
    at_reach = runtime.deform_faps({"open_jaw": reach})
    np.testing.assert_array_equal(runtime.deform_faps({"open_jaw": 40 * reach}), at_reach)
    assert 500 < reach < 2048  # well past what takes ask (the corpus opens to 573) and finite


@pytest.mark.parametrize("upper, lower, point_up, point_low",
                         [(19, 21, "3.1", "3.3"), (20, 22, "3.2", "3.4")])
def test_eyelids_never_cross(runtime, face, upper, lower, point_up, point_low):
    top, bottom = face.feature_vertices[point_up], face.feature_vertices[point_low]
    for u, d in ((2000, 2000), (5000, -100), (1024, 0), (900, 900), (1e20, 1e20)):
        moved = runtime.deform_faps({upper: u, lower: d})
        assert moved[top, 1] >= moved[bottom, 1] - 1e-9, (u, d)
    meet = runtime.deform_faps({upper: 1024, lower: 0})
    assert meet[top, 1] == pytest.approx(meet[bottom, 1], abs=1e-6)  # 1024 IRISD closes the lids exactly


def test_fap_1_and_2_fields_a_face_cannot_show_pose_as_none_or_held(runtime):
    from puppet.fap.highlevel import limit_fields

    viseme, expression = limit_fields(np.array([20, -3, 900, 0]), np.array([9, -5, 2, 1e12, 0, 0]))
    assert viseme == (0, 0, 63.0) and expression == (0, 0.0, 2, 63.0)
    assert np.isfinite(runtime.deform_faps({}, viseme=viseme, expression=expression)).all()


@settings(max_examples=25, deadline=None)
@given(st.lists(st.lists(st.sampled_from([0.0, 120.0, -300.0, 800.0, 20000.0]), min_size=68, max_size=68),
                min_size=2, max_size=5))
def test_rigid_motions_kept_between_frames_are_those_a_fresh_engine_makes(runtime, face, frames):
    """The engine remakes a part's motion only when the FAPs it follows change: over any
    sequence of frames each motion equals what an engine that never saw the earlier ones makes,
    and a kept motion cannot be changed by a caller."""
    for values in frames:
        values = np.array(values)
        values[:2] = 0.0
        d, motions = runtime.faps.controls(values)
        d0, motions0 = FapEngine(runtime).controls(values)
        np.testing.assert_array_equal(d, d0)
        assert motions.keys() == motions0.keys()
        for part in motions:
            np.testing.assert_array_equal(motions[part], motions0[part], err_msg=part)
    values = np.zeros(68)
    values[2] = 300.0  # open_jaw
    with pytest.raises(ValueError):
        runtime.faps.controls(values)[1]["jaw"][0, 3] = 1.0


def test_a_part_whose_faps_are_all_zero_is_at_rest_and_left_out(runtime):
    """The engine gives motions only for the parts that move: each part it leaves out would have
    been exactly the identity (so the runtime, which skips parts at rest, deforms the same)."""
    values = np.zeros(68)
    values[[2, 18]] = 300.0, 500.0  # open_jaw, close_t_l_eyelid
    assert set(runtime.faps.controls(values)[1]) == {"jaw", "upper_lid_l"}
    for part, (make, _) in runtime.faps._parts.items():
        np.testing.assert_array_equal(make(np.zeros(68)), IDENTITY, err_msg=part)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1000.0, 1000.0), min_size=68, max_size=68))
def test_control_point_displacements_are_each_fap_times_its_motion_summed(runtime, frame):
    """A frame's control point displacements are the sum over FAPs of each FAP's value (as the
    face shows it) times that FAP's motion of every point: the engine's product over the FAPs a
    frame shows gives the dense definition's sums, to float64 rounding (the runtime's dtype), on
    every point but the upper lid margins, which a closing lid also gives its closing shape
    (``tests/test_lidclosure.py``)."""
    values = np.array(frame)
    values[:2] = 0.0
    engine = runtime.faps
    shown = np.clip(engine.shown(values), engine.skin_reach[0], engine.skin_reach[1])
    expected = (engine._translations * shown).sum(axis=1).reshape(-1, 3)
    scale = max(np.abs(engine._translations).max() * np.abs(shown).sum(), 1e-300)
    kept = np.setdiff1d(np.arange(len(expected)), engine.closing_rows)
    np.testing.assert_allclose(engine.controls(values)[0][kept], expected[kept], rtol=0, atol=1e-13 * scale)
