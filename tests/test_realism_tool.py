"""tools/checks/realism.py: its cheap parts (fold counter, FAP ends, fits on a few example shapes, the
targets line) behave as the figures it prints claim."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import puppet
from puppet.bench.assets import shared_assets
from puppet.face.autorig import build_rig
from puppet.face.examples import load_examples
from tools.checks.realism import TARGETS, fap_ends, fits, fold_count, folds, residuals, summary, targets

EXAMPLES = shared_assets() / "makehuman" / "faceunits_arkit"


@pytest.fixture(scope="module")
def face():
    return puppet.load_face()


@pytest.fixture(scope="module")
def shipped(face):
    return puppet.Runtime(face)


@pytest.fixture(scope="module")
def examples(face):
    if not EXAMPLES.is_dir():
        pytest.skip(f"{EXAMPLES} is not here (../shared/assets/makehuman)")
    return load_examples(face, EXAMPLES)


def test_fap_ends_are_the_finite_nonzero_range_ends_of_faps_3_to_68():
    ends = fap_ends()
    assert {n for n, _ in ends} <= set(range(3, 69))
    assert all(np.isfinite(v) and v != 0 for _, v in ends)
    assert any(n == 3 and v > 0 for n, v in ends)  # open_jaw opens


def test_fold_count_counts_the_triangles_turned_over(face):
    assert fold_count(face, face.vertices) == 0
    square = SimpleNamespace(vertices=np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
                             triangles=np.array([[0, 1, 2], [0, 2, 3]]))
    pushed = square.vertices.copy()
    pushed[1] = [0.2, 0.8, 0]  # across the diagonal: the first triangle turns over, the second stays
    assert fold_count(square, pushed) == 1
    assert fold_count(square, square.vertices * [1, 1, 3]) == 0  # a stretch is no fold


def test_fold_report_lists_only_folding_faps_and_adds_them_up(face, shipped):
    report = folds(face, shipped)
    worst = report["faps"]["by_end"]
    assert all(count > 0 for count in worst.values())
    assert report["faps"]["total"] == sum(worst.values())
    assert report["visemes"]["0"] == 0  # viseme 0 is the neutral mouth
    assert set(report["expressions"]) == {"joy", "sadness", "anger", "fear", "disgust", "surprise"}


def test_fitted_smile_raises_its_own_lip_corner(face, shipped, examples):
    smiles = {name: examples[name] for name in ("mouthSmileLeft", "mouthSmileRight")}
    values = fits(shipped, smiles, "skin")
    rest = shipped.deform_faps()
    for name, corner, other in (("mouthSmileLeft", "8.3", "8.4"), ("mouthSmileRight", "8.4", "8.3")):
        moved = shipped.deform_faps(values[name]) - rest
        up = moved[face.feature_vertices[corner], 1]
        assert up > 0.1 * smiles[name][face.feature_vertices[corner], 1]
        assert up > moved[face.feature_vertices[other], 1] + 0.02  # a one-sided smile


def test_shipped_rig_fits_jaw_and_brow_closer_than_the_coarse_rig(face, shipped, examples):
    coarse = puppet.Runtime(face, build_rig(face, grid=False, calibrated=False))
    shapes = {name: examples[name] for name in ("jawOpen", "browInnerUp")}
    ours = residuals(shipped, shapes, fits(shipped, shapes, "moved"))
    theirs = residuals(coarse, shapes, fits(coarse, shapes, "moved"))
    assert all(ours[name] < 0.9 * theirs[name] for name in shapes), (ours, theirs)  # the jaw's fit keeps
    # within the lips' fold-free reach (puppet.runtime.foldlimits): 0.33 against the coarse rig's 0.39
    assert summary(ours)["worst_name"] == max(ours, key=ours.get)


def test_targets_line_says_met_or_missed_against_each_limit():
    report = {"held_out": {"side": {"held_out": {"median": 0.25}}, "groups": {"held_out": {"median": 0.5}}},
              "capacity": {"shipped": {"median": 0.35}},
              "folds": {"faps": {"total": 0}, "expressions": {"joy": 0}, "visemes": {"0": 0}},
              "mouth": {"dark": 0.30, "teeth": 0.05}}
    met = {name: t["met"] for name, t in targets(report).items()}
    assert met == {"held-out median (side)": True, "held-out median (groups)": False,
                   "capacity median": False, "folds": True,
                   "open mouth dark": True, "open mouth teeth": False}
    report["folds"]["expressions"]["joy"] = 1
    assert targets(report)["folds"] == {"value": 1, "target": TARGETS["folds"], "met": False}
