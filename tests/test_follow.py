"""A follow pair's range (puppet.runtime.follow): at rest the range the rig stores, narrowing to
nothing at the pair's common reach; the leader keeps its value and the follower moves as little
as brings the pair inside."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from puppet.runtime import follow

values = st.floats(-2000, 2000)
ranges = st.tuples(st.floats(-300, -1), st.floats(1, 300), st.floats(-900, -200), st.floats(200, 900))


def _inside(rows, a, b, tol=1e-6) -> bool:
    return bool(np.all(rows[:, 0] * a + rows[:, 1] * b - rows[:, 2] <= tol * (1 + abs(a) + abs(b))))


@given(ranges, values, values)
def test_the_leader_keeps_its_value_and_the_pair_ends_inside_within_the_common_reach(r, a, b):
    rows = follow.rows(*r)
    new_a, new_b = follow.follower(rows, a, b)
    lead_a = abs(a) >= abs(b)
    assert (new_a == a) if lead_a else (new_b == b)
    lead = a if lead_a else b
    if r[2] < lead < r[3]:  # both at the leader's value are inside: some follower value is
        assert _inside(rows, new_a, new_b)


@given(ranges, values, values)
def test_a_pair_already_inside_is_left_as_it_is(r, a, b):
    rows = follow.rows(*r)
    if _inside(rows, a, b, tol=-1e-9):
        assert follow.follower(rows, a, b) == (a, b)


@given(st.floats(-300, -1), st.floats(1, 300), values, values)
def test_without_a_common_reach_the_range_is_the_rest_range(low, high, a, b):
    """Rig files from before the common reach: the difference is kept within (low, high)."""
    new_a, new_b = follow.follower(follow.rows(low, high), a, b)
    assert new_a - new_b == pytest.approx(np.clip(a - b, low, high), abs=1e-9)
    if low + 1e-9 <= a - b <= high - 1e-9:
        assert (new_a, new_b) == (a, b)


def test_the_range_narrows_linearly_to_nothing_at_the_common_reach():
    rows = follow.rows(-100.0, 200.0, -400.0, 800.0)
    for m, width in ((0.0, 300.0), (400.0, 150.0), (800.0, 0.0), (-200.0, 150.0)):
        top = [g for g in np.linspace(-300, 300, 6001) if _inside(rows, m + g / 2, m - g / 2, tol=1e-9)]
        assert max(top) - min(top) == pytest.approx(width, abs=0.2)
