"""The sliver guard's corrective shapes (puppet.runtime.sliverguard): a lid's turn read back from
its rigid motion, the shapes blended by it, and a lid that never squeezes a corner getting none.
The blink's behaviour on the default face is in test_foldlimits.py."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from puppet.face import rigid
from puppet.runtime.sliverguard import Corrective, SliverGuard, _corrective, turn_about

AXES = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


@given(axis=AXES, angle=st.floats(-3.1, 3.1), pivot=st.tuples(*[st.floats(-5.0, 5.0)] * 3))
def test_a_turn_about_an_axis_is_read_back_from_its_motion(axis, angle, pivot):
    axis = np.asarray(axis) / np.linalg.norm(axis)
    motion = rigid.about(np.asarray(pivot), rigid.rotation(axis, angle))
    assert turn_about(motion, axis) == pytest.approx(angle, abs=1e-9)
    assert turn_about(motion, -axis) == pytest.approx(-angle, abs=1e-9)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_corrective_shape_is_nothing_before_its_onset_blended_between_and_held_beyond(sign):
    axis = np.array([1.0, 0.0, 0.0])
    fixes = np.array([np.zeros((2, 3)), np.full((2, 3), 1.0), np.full((2, 3), 3.0)])
    shape = Corrective("upper_lid_l", axis, sign * np.array([0.2, 0.3, 0.5]), fixes)

    def at(angle):
        return shape.at(rigid.about(np.zeros(3), rigid.rotation(axis, sign * angle)))

    assert at(0.0) is None and at(0.2) is None and at(-0.4) is None  # open, or not yet squeezing
    np.testing.assert_allclose(at(0.25), 0.5)
    np.testing.assert_allclose(at(0.4), 2.0)
    np.testing.assert_allclose(at(0.5), 3.0)
    np.testing.assert_allclose(at(0.9), 3.0)


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
