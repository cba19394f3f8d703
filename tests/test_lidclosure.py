"""The upper lids' closing shapes (puppet.runtime.lidclosure): a blink closes the whole eye."""

from __future__ import annotations

import copy
from types import SimpleNamespace

import numpy as np
import pytest

from puppet.fap.highlevel import fap_values
from puppet.runtime.lidclosure import ONSET, LidClosure
from puppet.runtime.musclesolver import folded_triangles
from tools.checks.eye_closure import opening

SIDES = [("l", 19, 21), ("r", 20, 22)]  # the eye, its upper and lower lid FAPs


@pytest.mark.parametrize("side, upper, lower", SIDES)
def test_a_blink_closes_the_whole_eye_and_folds_nothing(runtime, face, side, upper, lower):
    """The upper lid alone at 1024 IRISD leaves under 4% of the eye's opening (8.6% without the
    closing shape: the outer half 1.6 mm open, the white of the eye showing); with the lower lid
    taking the artists' share of the closing (800 + 224) under 1%. Nothing folds."""
    rest = opening(runtime, face.vertices, side)
    triangles = np.asarray(face.triangles)
    for pose, left in (({upper: 1024.0}, 0.04), ({upper: 800.0, lower: 224.0}, 0.01)):
        closed = runtime.deform_faps(pose)
        assert opening(runtime, closed, side) < left * rest, pose
        assert folded_triangles(face.vertices, closed, triangles).sum() == 0, pose


@pytest.mark.parametrize("side, upper, lower", SIDES)
def test_below_the_onset_a_lid_moves_as_its_faps_say(runtime, side, upper, lower):
    """Under ``ONSET`` of the closing the shape adds nothing; above it, it moves only its rows."""
    engine = runtime.faps
    for closing, shaped in ((ONSET - 0.01, False), (ONSET + 0.2, True)):
        values = fap_values({upper: 0.8 * closing * 1024.0, lower: 0.2 * closing * 1024.0})
        d = engine.controls(values)[0]
        plain = engine._shown_controls(engine.shown(values))[0]
        moved = np.flatnonzero(np.any(d != plain, axis=1))
        assert bool(len(moved)) == shaped
        assert set(moved) <= set(engine.closing_rows)


def test_the_closing_shapes_move_upper_margins_only_and_no_feature_point(runtime, face):
    """A FAP's own point moves by exactly value x FAPU, and the lower lid as its FAPs say: the
    shapes move the upper margins' other points alone, and the lid's point still drops exactly."""
    names = [runtime.control_points[i] for i in runtime.faps.closing_rows]
    attach = {p.name: p.attach for p in runtime.rig.control_points}
    assert names and not set(names) & set(face.feature_points)
    assert {attach[name] for name in names} == {"upper_lid_l", "upper_lid_r"}
    closed = runtime.deform_faps({19: 1024.0})
    lid = face.feature_vertices["3.1"]
    assert face.vertices[lid, 1] - closed[lid, 1] == pytest.approx(1024.0 * face.fapu["IRISD0"], abs=1e-9)


def test_the_margin_closes_smoothly_through_the_onset(runtime):
    """Step by 4 IRISD from half open to closed, no upper margin point moves more than 2.5 times
    its median step as DFFD deforms it (the sliver guard's corner fix, tested in
    ``test_foldlimits.py``, left out): the shape fades in with a smoothstep, it never jumps in."""
    unguarded = copy.copy(runtime)
    unguarded._slivers = None
    rows = [p.vertex for p in runtime.rig.control_points if p.attach == "upper_lid_l"]
    frames = np.array([unguarded.deform_faps({19: value})[rows] for value in np.arange(500.0, 1025.0, 4.0)])
    steps = np.linalg.norm(np.diff(frames, axis=0), axis=2)
    assert (steps.max(axis=0) < 2.5 * np.median(steps, axis=0)).all()


def test_a_rig_with_no_margin_points_on_a_lid_gets_no_closing_shape_for_it(runtime):
    """A rig made elsewhere may have the lid parts but carry no points on one of them: that side
    gets no closing shape (nothing to close), the other side its own."""
    points = [p for p in runtime.rig.control_points if p.attach != "lower_lid_r"]
    attach = {p.name: p.attach for p in runtime.rig.control_points}
    kept = [i for i, name in enumerate(runtime.control_points) if attach[name] != "lower_lid_r"]
    stub = SimpleNamespace(
        rig=SimpleNamespace(rigid_parts=runtime.rig.rigid_parts, control_points=points), face=runtime.face,
        control_points=[runtime.control_points[i] for i in kept], muscle_shares=runtime.muscle_shares[kept],
        control_positions=lambda d, rigid: runtime.control_positions(d, rigid)[kept])

    closure = LidClosure(stub, lambda values: runtime.faps._shown_controls(runtime.faps.shown(values)), 1024.0)
    assert [side.number for side in closure.sides] == [19]
