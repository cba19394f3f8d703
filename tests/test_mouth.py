"""The open mouth reads as a mouth: a dark cavity with teeth in it, the tongue behind the lower
incisors, the mouth bag behind the lips (issue 11)."""

from __future__ import annotations

import numpy as np
import pytest

import puppet
from puppet.face.autorig import _loop_path_via, build_rig
from puppet.view.mouthcheck import MouthPixels, middle_third, mouth_pixels

JAW_OPENINGS = np.arange(0.0, 1081.0, 120.0)


@pytest.fixture(scope="module")
def face():
    return puppet.load_face()


@pytest.fixture(scope="module")
def runtime(face):
    return puppet.Runtime(face, rig=build_rig(face))


@pytest.fixture(scope="module")
def open_mouth(face, runtime, egl):
    return mouth_pixels(face, runtime, open_jaw=400)


def test_open_mouth_is_mostly_dark_with_teeth_showing(open_mouth):
    assert open_mouth.area > 1000
    assert open_mouth.dark_fraction >= 0.25
    assert open_mouth.teeth_fraction >= 0.08


def test_middle_third_splits_the_width_the_mask_spans():
    """Issue 36: the check counts the teeth in the middle third of the opening, where the upper
    central incisors show, apart from the side teeth it counted with them."""
    mask = np.zeros((4, 12), dtype=bool)
    mask[1:3, 3:9] = True  # columns 3..8: the middle third is 5..6
    assert np.flatnonzero(middle_third(mask).any(axis=0)).tolist() == [5, 6]
    assert not middle_third(np.zeros((4, 12), dtype=bool)).any()
    m = MouthPixels(area=100, dark=10, teeth=30, middle=40, middle_teeth=20, middle_upper_teeth=8)
    assert (m.middle_teeth_fraction, m.middle_upper_teeth_fraction, m.side_teeth_fraction) == (0.5, 0.2, 10 / 60)


@pytest.mark.parametrize("expression", [4, 6])
def test_parted_lips_show_the_upper_front_teeth(face, runtime, egl, expression):
    """Issue 36: fear (4) and surprise (6) show the upper central incisors in the middle of the
    opening, as the artist's shapes do. Their edges sat 0.5 mm below the lips' meeting line, behind
    the upper lip's inner wall, and the middle of every open mouth was dark with side teeth only."""
    m = mouth_pixels(face, runtime, pose={"expression": (expression, 63, 0, 0)})
    assert m.middle_upper_teeth_fraction >= 0.05


def test_closed_mouth_shows_neither_cavity_nor_teeth(face, runtime, open_mouth):
    """At rest the lips meet (the face builder closes base.obj's slit behind them): what lies
    between them is their own dark crease, not the cavity, and no tooth (the slit showed the
    incisal edges as a white line, 40 px, a tenth of the open mouth's teeth)."""
    closed = mouth_pixels(face, runtime, open_jaw=0)
    assert closed.area < 0.15 * open_mouth.area  # the lips' slit only
    assert closed.dark + closed.teeth < 0.1 * open_mouth.area
    assert closed.teeth < 0.05 * open_mouth.teeth


def _mouth_bag(face) -> np.ndarray:
    from puppet.face.autorig import _Builder

    skin = face.parts["skin"]
    return skin[_Builder(face)._mouth_bag(skin)]


def test_tongue_stays_behind_the_lower_incisors(face, runtime):
    tongue, lower = face.parts["tongue"], face.parts["teeth_lower"]
    front = np.abs(face.vertices[lower, 0]) < 0.05  # the lower incisors
    for open_jaw in JAW_OPENINGS:
        v = runtime.deform_faps({"open_jaw": open_jaw})
        incisors = v[lower[front]]
        # in the jaw's frame the tongue rides with the teeth: compare along the jaw's forward axis
        assert v[tongue, 2].max() < incisors[:, 2].max(), open_jaw


def test_mouth_bag_never_comes_out_in_front_of_the_lips(face, runtime):
    bag = _mouth_bag(face)
    lips = np.asarray(face.contours["mouth_opening"])  # the inner lip line
    for open_jaw in JAW_OPENINGS:
        v = runtime.deform_faps({"open_jaw": open_jaw})
        assert v[bag, 2].max() <= v[lips, 2].max() + 1e-9, open_jaw


@pytest.mark.parametrize("rig", ["auto", "shipped"])
def test_the_lower_lip_parts_from_the_upper_all_the_way_to_the_corners(face, runtime, rig):
    """As the jaw opens, the lower lip's inner edge drops more the further it is from the corners,
    on both sides: the lips part evenly into each corner. Split from the upper lip at the mid-line's
    height, the edge beside each corner (which rises toward it) went with the upper lip and held
    there (open_jaw 1080: 8 mm of drop where its neighbour 5 mm in dropped 34): a web of lip
    across the opened mouth's corners."""
    posed = runtime if rig == "auto" else puppet.Runtime(face)
    loop, fv = list(np.asarray(face.contours["mouth_opening"])), face.feature_vertices
    lower = _loop_path_via(loop, loop.index(fv["2.4"]), loop.index(fv["2.5"]), fv["2.3"])
    middle = lower.index(fv["2.3"])
    for open_jaw in (400.0, 900.0):
        drop = face.vertices[lower, 1] - posed.deform_faps({"open_jaw": open_jaw})[lower, 1]
        for half in (drop[:middle + 1], drop[middle:][::-1]):  # corner to 2.3
            assert np.all(np.diff(half) >= -0.05 * drop.max()), (open_jaw, np.round(half, 3))
