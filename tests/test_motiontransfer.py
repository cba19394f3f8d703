"""Carrying the default face's calibration to other faces (puppet.face.motiontransfer, the grid's jaw
share in puppet.face.autorig) and judging the result (puppet.runtime.posecheck): on the default face
itself the transfer gives back every calibrated motion; a face whose jaw angles sit above its mouth
corners does not hang its upper face on the jaw; the default face bounds itself; a face of another
shape, written as a bare mesh and rigged from landmarks, fits the artist's shapes nearly as well
as the default face and smiles and looks surprised with few creases."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from puppet.bench.assets import shared_assets
from puppet.face.autorig import build_rig, rig_for_face
from puppet.face.default import default_face, load_default_rig
from puppet.face.examples import load_examples
from puppet.face.load import load_face
from puppet.face.motiontransfer import feature_warp
from puppet.runtime.posecheck import POSES, pose_flaws
from puppet.runtime.runtime import Runtime
from tools.checks.transfer_check import in_face_frame, median_residual, shaped_face

ARKIT = shared_assets() / "makehuman" / "faceunits_arkit"


@pytest.fixture(scope="module")
def reference():
    face = default_face()
    return Runtime(face, rig_for_face(face), cache=False)


@pytest.fixture(scope="module")
def shaped(tmp_path_factory):
    """A face one standard deviation of MakeHuman's people away from the default face, from a bare OBJ."""
    mesh, landmarks = shaped_face(tmp_path_factory.mktemp("shaped"), seed=1, spread=1.0)
    face = load_face(mesh, landmarks=landmarks)
    return Runtime(face, build_rig(face), cache=False)


def test_the_default_face_gets_back_every_calibrated_motion():
    shipped = load_default_rig()
    carried = build_rig(default_face()).fap_motions
    assert set(carried) == set(shipped.fap_motions)
    for number, motions in shipped.fap_motions.items():
        assert set(motions) <= set(carried[number]), number  # feature points' motions included
        for name in carried[number]:
            np.testing.assert_allclose(carried[number][name], motions.get(name, np.zeros(3)), atol=1e-6)


def test_two_feature_points_at_one_place_still_warp_the_face_onto_the_default():
    """Found landmarks can put two feature points on one vertex (10.6 and 10.8 on an ear): the warp
    keeps one of them and still takes every other feature point where it sits on the default face
    (with both, the spline's system was singular and its points landed 1e14 away)."""
    source = default_face().feature_points
    target = {k: v * 1.1 + 0.2 for k, v in source.items()}
    target["10.8"] = target["10.6"].copy()
    others = sorted(k for k in source if k != "10.8")
    warped = feature_warp(source, target)(np.array([target[k] for k in others]))
    np.testing.assert_allclose(warped, np.array([source[k] for k in others]), atol=1e-6)


def test_high_jaw_angles_leave_the_upper_face_off_the_jaw():
    face = default_face()
    corner_y = face.feature_points["8.3"][1]
    chin_y = face.feature_points["2.1"][1]
    raised = dict(face.feature_points)
    for angle in ("2.13", "2.14"):  # ICT's sit level with the ear lobes, well above the mouth
        raised[angle] = raised[angle] + [0, corner_y - chin_y, 0]
    contours = {k: v for k, v in face.contours.items() if k != "face_oval"}  # as a face from landmarks has
    rig = build_rig(dataclasses.replace(face, feature_points=raised, contours=contours), calibrated=False)
    points = {p.name: p for p in rig.control_points}
    for region in rig.regions:
        if region.name in ("forehead", "nose"):
            assert not [n for n in region.control_points if points[n].attach == "jaw"], region.name
    on_jaw = [p for p in rig.control_points if "_grid_" in p.name and p.attach == "jaw"]
    assert on_jaw and max(face.vertices[p.vertex][1] for p in on_jaw) < corner_y


def test_the_default_face_bounds_itself(reference):
    assert all(f.folds == 0 and f.creases == 0 for f in pose_flaws(reference, reference).values())


@pytest.mark.skipif(not ARKIT.is_dir(), reason="needs the MakeHuman ARKit shapes in ../shared/assets")
def test_a_shaped_face_fits_the_artists_shapes_nearly_as_well(reference, shaped):
    shapes = load_examples(reference.face, ARKIT)
    shapes = {k: shapes[k] for k in ("browInnerUp", "jawOpen", "mouthSmileLeft")}
    own = median_residual(reference, shapes)
    assert median_residual(shaped, in_face_frame(shaped.face, shapes)) <= own + 0.10


def test_a_shaped_face_smiles_and_looks_surprised_with_few_creases(reference, shaped):
    flaws = pose_flaws(shaped, reference, {k: POSES[k] for k in ("joy", "surprise")})
    for name, found in flaws.items():
        assert found.folds <= 20 and found.creases <= 0.03 * found.edges, (name, found)
