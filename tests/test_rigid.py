"""Rigid motions of the face's parts."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.face import rigid


@settings(max_examples=100, deadline=None)
@given(st.tuples(*[st.floats(-1, 1)] * 3), st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda a: sum(x * x for x in a) > 1e-3),
       st.floats(-3.2, 3.2), st.tuples(*[st.floats(-0.1, 0.1)] * 3))
def test_a_turn_in_scalar_math_is_the_rotation_about_its_pivot(pivot, axis, angle, shift):
    """``rigid.turn``, which the jaw and lids use every frame, is ``about(pivot, rotation(...), shift)``."""
    expected = rigid.about(np.array(pivot), rigid.rotation(np.array(axis), angle), np.array(shift))
    np.testing.assert_allclose(rigid.turn(pivot, axis, angle, shift), expected, atol=1e-14)
