"""Skin smoothing (``puppet.runtime.skinsmoothing``) and where a rig gets it
(``puppet.runtime.creasesmoothing``): it spreads a hinge over the rings around it, leaves every
vertex it does not list as it was, and keeps rest and translations; the runtime folds it into B, in
both modes; a finer mesh of the default face creases less with it (a face as coarse as the default
face gets none: ``test_autorig``)."""

import copy

import numpy as np
import pytest
import trimesh.remesh
from hypothesis import given, settings
from hypothesis import strategies as st
from test_creases import sheet

from puppet.face.autorig import build_rig
from puppet.face.default import load_default_rig
from puppet.face.load import load_face
from puppet.face.meshfile import write_bare_obj
from puppet.runtime.creases import Hinges
from puppet.runtime.creasesmoothing import crease_smoothed
from puppet.runtime.posecheck import PoseCheck
from puppet.runtime.runtime import Runtime
from puppet.runtime.skinsmoothing import skin_triangles, smoothing_matrix


def tent(vertices: np.ndarray) -> np.ndarray:
    """A motion field that lifts the sheet by 0.3 (1 - |x|): a hinge along x = 0, flat elsewhere."""
    out = np.zeros_like(vertices)
    out[:, 2] = 0.3 * (1 - np.abs(vertices[:, 0]))
    return out


def test_smoothing_spreads_a_hinge_over_the_rings_around_it():
    vertices, triangles = sheet(12)
    hinges = Hinges.of(triangles)
    motion = tent(vertices)
    band = np.flatnonzero(np.abs(vertices[:, 0]) < 0.4)
    smoothed = smoothing_matrix(triangles, len(vertices), band) @ motion
    before = np.abs(hinges.bend(vertices, vertices + motion, triangles))
    after = np.abs(hinges.bend(vertices, vertices + smoothed, triangles))
    assert after.max() < 0.5 * before.max()
    outside = np.setdiff1d(np.arange(len(vertices)), band)
    np.testing.assert_array_equal(smoothed[outside], motion[outside])


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 6))
def test_unlisted_vertices_keep_their_motion_and_translations_stay(seed, passes):
    vertices, triangles = sheet(6)
    rng = np.random.default_rng(seed)
    listed = np.flatnonzero(rng.random(len(vertices)) < 0.5)
    S = smoothing_matrix(triangles, len(vertices), listed, passes)
    np.testing.assert_allclose(np.asarray(S.sum(axis=1)).ravel(), 1.0)
    unlisted = np.setdiff1d(np.arange(len(vertices)), listed)
    identity = np.eye(len(vertices))[unlisted]
    np.testing.assert_array_equal(S[unlisted].toarray(), identity)
    shift = np.tile(rng.normal(size=3), (len(vertices), 1))
    np.testing.assert_allclose(S @ shift, shift)


def test_the_mean_stays_on_the_triangles_given():
    """Two sheets side by side, not joined: smoothing one never takes the other's motion."""
    vertices, triangles = sheet(4)
    both = np.r_[vertices, vertices + [3, 0, 0]]
    S = smoothing_matrix(np.r_[triangles, triangles + len(vertices)], len(both), np.arange(len(vertices)))
    assert S[: len(vertices), len(vertices):].nnz == 0


def test_the_runtime_folds_the_smoothing_into_b_in_both_modes(face, runtime):
    """A rig's smoothed vertices move as the smoothing of the unsmoothed motion (up to B's pruning),
    in the real-time mode too; a copy made by ``with_smoothing`` deforms as a runtime built on
    that rig."""
    mouth = np.flatnonzero(np.linalg.norm(face.vertices - face.feature_points["2.2"], axis=1) < 0.15)
    mouth = mouth[runtime.dffd_vertices[mouth]]
    copied = runtime.with_smoothing(mouth)
    rig = copy.copy(runtime.rig)
    rig.smoothed = mouth
    built = Runtime(face, rig)
    pose = {"expression": (1, 63, 0, 0)}
    np.testing.assert_allclose(copied.deform_faps(**pose), built.deform_faps(**pose), atol=1e-5)
    d = np.random.default_rng(2).normal(scale=0.01, size=(len(runtime.control_points), 3))
    plain = runtime.deform(d) - runtime.rest
    S = smoothing_matrix(skin_triangles(face), len(runtime.rest), mouth)
    expected = runtime.rest + S @ plain
    assert np.abs(built.deform(d) - expected).max() < 0.01 * np.abs(plain).max()
    assert np.abs(built.deform(d)[mouth] - runtime.deform(d)[mouth]).max() > 0.1 * np.abs(plain[mouth]).max()
    realtime = Runtime(face, runtime.rig, mode="realtime").deform(d) - runtime.rest
    smoothed_in_realtime = Runtime(face, rig, mode="realtime").deform(d)
    np.testing.assert_allclose(smoothed_in_realtime, runtime.rest + S @ realtime, atol=1e-5)


@pytest.fixture(scope="module")
def reference(face):
    return Runtime(face, load_default_rig(), guard=False)


@pytest.mark.slow
def test_a_finer_mesh_of_the_default_face_creases_less_once_smoothed(face, reference, tmp_path):
    """The default face cut into four times the triangles (a user's denser mesh of the same head),
    rigged by transfer: the expressions and visemes crease far more than on the default face's own
    mesh, where a hinge falls on one long edge; smoothed where they crease, a quarter fewer edges."""
    vertices, triangles = trimesh.remesh.subdivide(face.vertices, face.triangles)
    mesh = write_bare_obj(tmp_path / "fine.obj", vertices, triangles)
    fine = load_face(mesh, landmarks=dict(face.feature_vertices))
    unsmoothed = Runtime(fine, build_rig(fine), guard=False)
    smoothed = crease_smoothed(unsmoothed, reference)
    check = PoseCheck(fine, reference)
    before = sum(f.creases for f in check.flaws(unsmoothed).values())
    after = sum(f.creases for f in check.flaws(smoothed).values())
    assert len(smoothed.rig.smoothed) > 0.1 * len(vertices)
    assert after < 0.8 * before
    placed = list(fine.feature_vertices.values())
    assert not np.isin(placed, smoothed.rig.smoothed).any()
