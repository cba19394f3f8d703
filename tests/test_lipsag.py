"""The lower lip's sag: how far a pose drops its middle below its sides."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.face.lipsag import lower_lip_sag


@given(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2), st.floats(-0.2, 0.2))
@settings(max_examples=25, deadline=None)
def test_a_lip_moved_as_one_does_not_sag(face, dx, dy, dz):
    assert abs(lower_lip_sag(face, np.tile([dx, dy, dz], (len(face.vertices), 1)))) < 1e-12


def test_the_middle_dropped_alone_sags_by_its_drop_and_raised_rises(face):
    for drop in (0.03, -0.01):
        displacement = np.zeros_like(face.vertices)
        displacement[face.feature_vertices["8.2"], 1] = -drop
        assert lower_lip_sag(face, displacement) == np.float64(drop)


def test_the_sides_raised_past_the_middle_make_a_v(face):
    displacement = np.zeros_like(face.vertices)
    for side in ("8.7", "8.8"):
        displacement[face.feature_vertices[side], 1] = 0.02
    assert lower_lip_sag(face, displacement) == 0.02
