"""The crease measure (``puppet.runtime.creases``): a sheet bent by a known angle reports that angle
on its hinge line and nothing elsewhere; rest and rigid motions bend nothing; a bound from a
reference pose lets that pose through and catches a sharper one."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from puppet.runtime.creases import MARGIN, CreaseReference, Hinges, largest_bend_near


def sheet(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A flat square sheet in the xy plane, x and y in [-1, 1], facing +z, split into triangles."""
    xs = np.linspace(-1, 1, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    vertices = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    b, c, d = a + n + 1, a + 1, a + n + 2
    return vertices, np.r_[np.c_[a, b, d], np.c_[a, d, c]]


def bent(vertices: np.ndarray, angle: float) -> np.ndarray:
    """The sheet with its x > 0 half turned about the y axis by ``angle``."""
    out = vertices.copy()
    right = vertices[:, 0] > 0
    out[right] = Rotation.from_rotvec([0, angle, 0]).apply(vertices[right])
    return out


def test_interior_edges_only():
    _, triangles = sheet(6)
    hinges = Hinges.of(triangles)
    all_edges = {tuple(sorted(e)) for t in triangles for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    border = 4 * 6
    assert len(hinges.edges) == len(all_edges) - border
    assert (hinges.left != hinges.right).all()


@pytest.mark.parametrize("angle", [0.2, -0.5, 1.0])
def test_bent_sheet_reports_its_angle_on_the_hinge_line(angle):
    vertices, triangles = sheet(6)
    hinges = Hinges.of(triangles)
    bend = hinges.bend(vertices, bent(vertices, angle), triangles)
    on_line = (np.abs(vertices[hinges.edges, 0]) < 1e-12).all(axis=1)
    assert on_line.sum() == 6
    assert np.allclose(np.abs(bend[on_line]), abs(angle))
    assert np.allclose(bend[~on_line], 0, atol=1e-12)


def test_rest_and_rigid_motion_bend_nothing():
    vertices, triangles = sheet(5)
    vertices = vertices + 0.1 * np.random.default_rng(3).normal(size=vertices.shape)  # not flat
    hinges = Hinges.of(triangles)
    assert np.allclose(hinges.bend(vertices, vertices, triangles), 0)
    moved = Rotation.from_rotvec([0.3, -1.1, 2.0]).apply(vertices) * 2.5 + [4, -2, 1]
    assert np.allclose(hinges.bend(vertices, moved, triangles), 0, atol=1e-9)


def test_a_reference_pose_bounds_the_same_pose_and_catches_a_sharper_one():
    vertices, triangles = sheet(6)
    hinges = Hinges.of(triangles)
    hinge = hinges.hinge_lengths(vertices, triangles)
    reference = CreaseReference.of(vertices, triangles, eye_separation=1.0)
    nearest = reference.nearest(hinges.midpoints(vertices))
    allowed = reference.allowed(bent(vertices, 0.4), nearest, hinge)
    assert not (np.abs(hinges.bend(vertices, bent(vertices, 0.4), triangles)) > allowed).any()
    sharper = np.abs(hinges.bend(vertices, bent(vertices, 0.4 + 2 * MARGIN), triangles)) > allowed
    on_line = (np.abs(vertices[hinges.edges, 0]) < 1e-12).all(axis=1)
    assert sharper[on_line].all() and not sharper[~on_line].any()
    allowed = reference.allowed(vertices, nearest, hinge)
    assert (np.abs(hinges.bend(vertices, bent(vertices, 0.4), triangles)) > allowed).sum() == 6


def test_the_largest_bend_near_a_point_sees_the_hinge_only_within_reach():
    """On a sheet standing in for a face (its skin all of it, 2 wide), the bend near a point on the
    hinge line is the sheet's angle; near a point farther from the line than the reach, nothing."""
    vertices, triangles = sheet(6)
    on_line, far = 3 * 7 + 3, 0  # the middle vertex (x = 0) and a corner (x = -1)
    face = SimpleNamespace(vertices=vertices, triangles=triangles, parts={"skin": np.arange(len(vertices))},
                           feature_vertices={"on": on_line, "far": far})
    posed = bent(vertices, 0.5)
    assert largest_bend_near(face, posed, ("on",), 0.1) == pytest.approx(np.degrees(0.5))
    assert largest_bend_near(face, posed, ("far",), 0.3) == 0.0
    assert largest_bend_near(face, posed, ("far", "on"), 0.1) == pytest.approx(np.degrees(0.5))
