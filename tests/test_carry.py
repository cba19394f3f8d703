"""The inputs attached to rigid parts ride on their parts' motions, batched across parts."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.face import rigid
from puppet.runtime.carry import Carry

ROWS = {"jaw": np.array([1, 4, 5]), "upper_lid_l": np.array([2]), "lower_lid_l": np.array([6, 7])}
N = 9


def _carry(seed: int) -> Carry:
    rng = np.random.default_rng(seed)
    return Carry({part: (rows, rng.normal(size=(len(rows), 3)), rng.uniform(0, 1, (len(rows), 1)))
                  for part, rows in ROWS.items()})


def _motion(angle: float, axis: tuple, shift: tuple) -> np.ndarray:
    return rigid.about(np.array([0.1, -0.2, 0.3]), rigid.rotation(np.array(axis), angle), np.array(shift))


motions = st.builds(_motion, st.floats(-1.5, 1.5), st.sampled_from([(1, 0, 0), (0, 1, 1), (1, 2, 3)]),
                    st.tuples(*[st.floats(-0.05, 0.05)] * 3))
moving = st.dictionaries(st.sampled_from(sorted(ROWS)), motions)


@settings(max_examples=60, deadline=None)
@given(moving, st.integers(0, 1000))
def test_each_attached_point_rides_its_own_parts_motion_by_its_weight(rigid_motions, seed):
    carry = _carry(seed)
    own = np.random.default_rng(seed + 1).normal(scale=0.01, size=(N, 3))
    out = own.copy()
    carry.carry(out, rigid_motions)
    for part, (rows, p0, w) in carry.parts.items():
        if part in rigid_motions:
            moved = rigid.apply(rigid_motions[part], p0 + own[rows]) - p0
            np.testing.assert_allclose(out[rows], w * moved + (1 - w) * own[rows], atol=1e-12)
        else:
            assert np.array_equal(out[rows], own[rows])  # a part at rest leaves its points exactly
    free = np.setdiff1d(np.arange(N), np.concatenate(list(ROWS.values())))
    assert np.array_equal(out[free], own[free])


@settings(max_examples=60, deadline=None)
@given(moving, st.integers(0, 1000))
def test_an_addition_is_carried_by_the_rotations_alone(rigid_motions, seed):
    """``turn``: carrying d + e gives carrying d plus turning e (the carry is affine)."""
    carry = _carry(seed)
    rng = np.random.default_rng(seed + 2)
    d, e = rng.normal(scale=0.01, size=(2, N, 3))
    whole, part, extra = d + e, d.copy(), e.copy()
    carry.carry(whole, rigid_motions)
    carry.carry(part, rigid_motions)
    carry.turn(extra, rigid_motions)
    np.testing.assert_allclose(whole, part + extra, atol=1e-12)


def test_the_key_follows_the_carrying_parts_motions_only():
    carry = _carry(0)
    jaw = _motion(0.2, (1, 0, 0), (0, 0, 0))
    assert carry.key({"jaw": jaw}) == carry.key({"jaw": jaw, "head": _motion(0.1, (0, 1, 1), (0, 0, 0))})
    assert carry.key({"jaw": jaw}) != carry.key({"jaw": _motion(0.3, (1, 0, 0), (0, 0, 0))})

