"""The fold-limit search with few deformations (puppet.runtime.foldsearch) finds what the plain
bisection finds, and its limits fold nothing while just past them the face folds."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import puppet
from puppet.fap.table import clamp_ranges
from puppet.runtime.fapcalibration import common_reach
from puppet.runtime.foldlimits import LIP_PAIRS, fold_limits
from puppet.runtime.foldsearch import Bisection, FoldSearch
from puppet.runtime.musclesolver import folded_triangles

STEPS = 12
SAMPLE = ([3], [4], [6], [12], [19], [31], [35], [53], [59], [12, 59], [6, 53])
"""FAPs (and lip pairs moved together) searched: the jaw and an upper lid turn, the lips follow."""


@pytest.fixture(scope="module")
def unlimited(face):
    """The default face's runtime (float32, as ``puppet rig`` searches) on its rig without limits,
    nor the fold guard's watch over what the shipped poses fold (``fold_limits`` drops both)."""
    rig = copy.copy(puppet.Runtime(face).rig)
    rig.fap_follow, rig.fap_reach, rig.guarded = {}, {}, np.zeros(0, dtype=np.int64)
    return puppet.Runtime(face, rig)


@pytest.fixture(scope="module", params=["no follow", "follow"])
def searched(request, unlimited, face):
    """(runtime, FoldSearch) without follow, and with the shipped rig's follow (the lip FAPs'
    motion bends where the other lip point starts to follow)."""
    follow = {} if request.param == "no follow" else puppet.Runtime(face).rig.fap_follow
    return unlimited.with_limits(follow), FoldSearch(unlimited).with_follow(follow)


def _folds(runtime, numbers, value) -> bool:
    values = np.zeros(68)
    values[np.asarray(numbers) - 1] = value
    return bool(folded_triangles(runtime.rest, runtime.deform_faps(values), runtime.face.triangles).any())


@pytest.mark.parametrize("numbers", SAMPLE, ids=str)
def test_the_search_finds_what_the_plain_bisection_finds(searched, numbers):
    runtime, search = searched
    assert common_reach(runtime, numbers, reach=search) == common_reach(runtime, numbers)


@pytest.mark.parametrize("numbers", SAMPLE, ids=str)
def test_nothing_folds_at_a_limit_and_the_face_folds_just_past_it(searched, numbers):
    """Just past: one step of the bisection (a 4096th of twice the range end) and the 0.1 the
    value is rounded to."""
    runtime, search = searched
    low, high = clamp_ranges()
    index = np.asarray(numbers) - 1
    ends = (np.max(low[index]), np.min(high[index]))
    for limit, end in zip(common_reach(runtime, numbers, reach=search), ends):
        if not np.isfinite(limit):
            assert not _folds(runtime, numbers, 2 * end)
            continue
        assert not _folds(runtime, numbers, limit)
        assert _folds(runtime, numbers, limit + np.sign(end) * (abs(2 * end) / 2 ** STEPS + 0.1))


def test_a_follow_changes_the_fap_engine_alone(unlimited, face):
    """``Runtime.with_limits`` shares the deformers and the sliver guard: it deforms every pose as
    a runtime set up anew with that follow does, to the bit."""
    follow = puppet.Runtime(face).rig.fap_follow
    rig = copy.copy(unlimited.rig)
    rig.fap_follow = follow
    fresh, shared = puppet.Runtime(face, rig), unlimited.with_limits(follow)
    assert shared.B is unlimited.B and shared.faps is not unlimited.faps
    for pose in ({12: 600.0}, {59: -300.0, 31: -80.0}, {3: 500.0, 19: 1024.0}, {6: 120.0, 53: -40.0}):
        np.testing.assert_array_equal(shared.deform_faps(pose), fresh.deform_faps(pose))
    assert unlimited.rig.fap_follow == {}


@pytest.mark.slow
def test_the_default_face_s_limits_are_the_plain_search_s(unlimited):
    """The whole search (follow, then each FAP's reach under it) to the digit."""
    fast = fold_limits(unlimited, FoldSearch)
    assert fast == fold_limits(unlimited, Bisection)
    assert len(fast[0]) == len(LIP_PAIRS)


@pytest.mark.parametrize("timeout", [120.0, 0.0], ids=["answered", "given up"])
def test_the_ends_searched_ahead_on_every_core_are_the_ones_asked_one_by_one(unlimited, monkeypatch, timeout):
    """``ahead`` searches every end a reach will ask for in forked processes; their values are what
    the search finds asked one by one. Processes that do not answer in time are given up, and their
    ends searched here, with no warning shown either way."""
    import warnings

    import puppet.runtime.forked as forked
    from puppet.runtime.fapcalibration import fold_free_reach

    monkeypatch.setattr(forked, "WORKERS", 2)
    monkeypatch.setattr(forked, "TIMEOUT", timeout)
    ahead = FoldSearch(unlimited)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ahead.ahead(lambda reach: fold_free_reach(unlimited, numbers=[3, 4, 5], reach=reach))
    assert len(ahead._found) == 5
    one_by_one = FoldSearch(unlimited)
    assert (fold_free_reach(unlimited, numbers=[3, 4, 5], reach=ahead)
            == fold_free_reach(unlimited, numbers=[3, 4, 5], reach=one_by_one))
    assert ahead._found == one_by_one._found
