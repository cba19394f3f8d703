"""The sliver guard's corrective shapes (puppet.runtime.sliverguard): a lid's turn read back from
its rigid motion, the shapes blended by it and by how far the brows are lowered, and a lid that
never squeezes a corner getting none, and a fix that would show more folds than it found left
unshown. The blink's behaviour on the default face is in test_foldlimits.py."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from puppet.face import rigid
from puppet.runtime.musclesolver import folded_triangles
from puppet.runtime.runtime import Runtime
from puppet.runtime.sliverguard import Corrective, Frown, SliverGuard, TurnShape, _corrective, turn_about

AXES = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


@given(axis=AXES, angle=st.floats(-3.1, 3.1), pivot=st.tuples(*[st.floats(-5.0, 5.0)] * 3))
def test_a_turn_about_an_axis_is_read_back_from_its_motion(axis, angle, pivot):
    axis = np.asarray(axis) / np.linalg.norm(axis)
    motion = rigid.about(np.asarray(pivot), rigid.rotation(axis, angle))
    assert turn_about(motion, axis) == pytest.approx(angle, abs=1e-9)
    assert turn_about(motion, -axis) == pytest.approx(-angle, abs=1e-9)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_turn_shape_is_nothing_before_its_onset_blended_between_and_held_beyond(sign):
    fixes = np.array([np.zeros((2, 3)), np.full((2, 3), 1.0), np.full((2, 3), 3.0)])
    shape = TurnShape(sign * np.array([0.2, 0.3, 0.5]), fixes)

    def at(angle):
        return shape.at(sign * angle)

    assert at(0.0) is None and at(0.2) is None and at(-0.4) is None  # open, or not yet squeezing
    np.testing.assert_allclose(at(0.25), 0.5)
    np.testing.assert_allclose(at(0.4), 2.0)
    np.testing.assert_allclose(at(0.5), 3.0)
    np.testing.assert_allclose(at(0.9), 3.0)


def test_a_turn_shape_that_squeezes_from_open_holds_its_first_fix_before_it():
    """Where something else (a deep frown) squeezes the corner with the lid open, the shape's first
    fix is not nothing: it holds below its first turn rather than jumping in at it."""
    shape = TurnShape(np.array([0.0, 0.4]), np.stack([np.full((1, 3), 2.0), np.full((1, 3), 4.0)]))
    for angle, fix in ((-0.2, 2.0), (0.0, 2.0), (0.2, 3.0), (0.6, 4.0)):
        np.testing.assert_allclose(shape.at(angle), fix)


@pytest.mark.parametrize(("lid", "depth"), [(0.0, 0.0), (1024.0, 0.0), (600.0, 0.4), (1080.0, 1.0), (300.0, 1.7),
                                            (800.0, -0.5)])
def test_a_frown_is_read_as_its_share_of_the_full_frown_whatever_the_lids_do(runtime, lid, depth):
    """The left lid's shapes read how far the left brows are lowered toward their reach (capped at
    it, brows raised reading none), however the lids move: an artist's blink moves some of the same
    control points."""
    shape = next(shape for shape in runtime._slivers.shapes if shape.part == "upper_lid_l")
    values = np.zeros(68)
    values[[18, 19, 20, 21]] = lid, lid, lid / 20, lid / 20
    brows = [30, 32, 34]  # raise_l_i/m/o_eyebrow
    values[brows] = depth * runtime.faps.reach[0][brows]
    controls = runtime.fap_controls(values)[0]
    assert shape.frown.depth(controls) == pytest.approx(min(max(depth, 0.0), 1.0), abs=1e-9)


def test_a_corrective_shape_reads_the_lid_s_turn_and_blends_the_frowns_it_was_sampled_at():
    """The lid's turn is read from its rigid motion, in either sense about its axis; between the
    lid alone and the full frown the fixes blend by the frown's depth; a frown that starts to
    squeeze sooner than the lid alone blends with nothing there."""
    axis = np.array([1.0, 0.0, 0.0])
    alone = TurnShape(np.array([0.3, 0.4]), np.stack([np.zeros((1, 3)), np.full((1, 3), 1.0)]))
    frowned = TurnShape(np.array([0.2, 0.4]), np.stack([np.zeros((1, 3)), np.full((1, 3), 3.0)]))
    frown = Frown(np.array([0]), np.array([[0.0, -1.0, 0.0]]))  # the full frown: the point 1 down
    shape = Corrective("upper_lid_l", axis, [alone, frowned], np.array([0.0, 1.0]), frown)

    def at(angle, lowered=None, about=axis):
        motion = rigid.about(np.zeros(3), rigid.rotation(about, angle))
        return shape.at(motion, None if lowered is None else np.array([[0.0, -lowered, 0.0]]))

    np.testing.assert_allclose(at(0.4, 0.25), 1.5)
    np.testing.assert_allclose(at(-0.4, 0.25, -axis), 1.5)
    np.testing.assert_allclose(at(0.4, 2.0), 3.0)  # beyond the full frown: held
    np.testing.assert_allclose(at(0.4, -0.5), 1.0)  # brows raised: the lid alone
    np.testing.assert_allclose(at(0.4), 1.0)  # no frown given
    np.testing.assert_allclose(at(0.3, 0.5), 0.5 * 1.5)  # the lid alone not yet squeezing
    assert at(0.2, 0.5) is None and at(0.1, 1.0) is None


def test_a_lid_that_squeezes_no_watched_corner_gets_no_shape(runtime, face):
    """On a face where only one lid's corners fold (a photo face need not be symmetric), the other
    lid gets no corrective shape: here the guard watches the left eye's corners alone."""
    runtime = copy.copy(runtime)
    runtime._slivers = None  # shapes are made from the runtime's poses before it has a guard
    probe = runtime.deform(*runtime.fap_controls({"close_t_l_eyelid": 1080.0})).astype(float)
    movable = runtime.dffd_vertices.copy()
    movable[list(face.feature_vertices.values())] = False
    guard = SliverGuard(face.vertices, face.triangles, movable, [probe])
    assert _corrective(runtime, guard, 20, 1080.0) is None
    assert _corrective(runtime, guard, 19, 1080.0).part == "upper_lid_l"


def test_the_guard_shows_no_fix_that_turns_more_triangles_over_than_it_found(runtime, face):
    """Pursed lips (viseme U) squeeze the slivers inside the lip corners that the shipped rig
    watches for joy's smile; the springs cannot hold them there, and their fallback drew the skin
    beside the corners 4.9 mm toward rest and turned 4 triangles over, where the pose alone turns
    none. The guard leaves such a pose as it is."""
    rig = copy.copy(runtime.rig)
    rig.guarded = np.zeros(0, dtype=np.int64)
    plain = Runtime(face, rig).deform_faps(viseme=(14, 0, 63))
    shown = runtime.deform_faps(viseme=(14, 0, 63))
    triangles = np.asarray(face.triangles)
    assert len(runtime.rig.guarded) and not folded_triangles(face.vertices, plain, triangles).any()
    assert not folded_triangles(face.vertices, shown, triangles).any()
    assert np.abs(shown - plain).max() < 1e-3
