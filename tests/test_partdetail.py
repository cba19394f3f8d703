"""Levels of detail: eyeballs and teeth seen small are drawn from fewer triangles, and the face
looks the same; seen close, every triangle is drawn."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.view.partdetail import FINE_EDGE_PX, PartDetail
from puppet.view.renderer import Renderer
from puppet.view.rendertake import aim_at_head

OPEN_MOUTH = {"open_jaw": 1200, "stretch_l_cornerlip": 300, "stretch_r_cornerlip": 300,
              "lower_t_midlip": -300, "raise_b_midlip": -200}
"""A wide open mouth: the teeth, tongue and the inside of the lips in view."""


@pytest.fixture(scope="module")
def detail(face) -> PartDetail:
    return PartDetail(face.vertices, face.triangles, face.parts, face.colors)


@pytest.fixture(scope="module")
def open_mouth(runtime):
    vertices = runtime.deform_faps(OPEN_MOUTH)
    return vertices, runtime.normals(vertices)


def _render(face, pose, size, view="front", detail=True, close_up=False) -> tuple[np.ndarray, dict]:
    with Renderer.for_face(face, width=size[0], height=size[1], detail=detail) as renderer:
        if close_up:
            renderer.aim(face.vertices[face.parts["teeth_upper"]], view=view, margin=2.0)
        else:
            aim_at_head(renderer, face, view)
        return renderer.render(*pose), renderer.levels


def test_the_inner_parts_are_set_apart_from_the_skin(face, detail):
    assert set(detail.parts) == {"eye_l", "eye_r", "teeth_lower", "teeth_upper", "tongue"}
    skin = np.zeros(len(face.vertices), bool)
    skin[face.parts["skin"]] = True
    assert skin[detail.whole].all(axis=1).sum() == skin[face.triangles].all(axis=1).sum()
    every = np.concatenate([detail.whole, *(p.triangles for p in detail.parts.values())])
    assert sorted(map(tuple, np.sort(every, axis=1))) == sorted(map(tuple, np.sort(face.triangles, axis=1)))


def test_at_the_live_window_size_eyes_and_teeth_are_drawn_from_a_third_of_the_triangles(face, egl):
    with Renderer.for_face(face, width=640, height=480) as renderer:
        aim_at_head(renderer, face, "front")
        renderer.render(face.vertices.astype("f4"))
        levels = renderer.levels
        drawn = len(renderer.detail.triangles(levels))
    assert levels == {"eye_l": "coarse", "eye_r": "coarse", "teeth_lower": "coarse", "teeth_upper": "coarse",
                      "tongue": "fine"}
    assert drawn < 0.65 * len(face.triangles)
    for name in ("eye_l", "teeth_upper"):
        part = renderer.detail.parts[name]
        coarse = renderer.detail.triangles({name: "coarse"})
        assert len(coarse) - len(renderer.detail.triangles({})) <= -0.6 * len(part.triangles)


@pytest.mark.parametrize("view", ["front", "three_quarter"])
def test_the_face_looks_the_same_drawn_from_fewer_triangles(face, open_mouth, egl, view):
    whole, _ = _render(face, open_mouth, (640, 480), view, detail=False)
    coarse, levels = _render(face, open_mouth, (640, 480), view)
    assert "coarse" in levels.values()
    diff = np.abs(whole.astype(int) - coarse.astype(int))
    assert diff.mean() < 0.2  # of 255
    assert (diff.max(axis=2) > 8).mean() < 0.005


def test_a_close_up_draws_every_triangle(face, open_mouth, egl):
    whole, _ = _render(face, open_mouth, (640, 480), detail=False, close_up=True)
    drawn, levels = _render(face, open_mouth, (640, 480), close_up=True)
    assert set(levels.values()) == {"fine"}
    assert np.abs(whole.astype(int) - drawn.astype(int)).max() <= 1


def test_a_small_image_draws_the_tongue_coarse_too(face, egl):
    with Renderer.for_face(face, width=160, height=120) as renderer:
        aim_at_head(renderer, face, "front")
        renderer.render(face.vertices.astype("f4"))
        assert set(renderer.levels.values()) == {"coarse"}


def test_the_level_follows_the_camera(face, open_mouth, egl):
    with Renderer.for_face(face, width=640, height=480) as renderer:
        aim_at_head(renderer, face, "front")
        far = renderer.render(*open_mouth)
        assert renderer.levels["teeth_upper"] == "coarse"
        renderer.aim(face.vertices[face.parts["teeth_upper"]], margin=2.0)
        near = renderer.render(*open_mouth)
        assert set(renderer.levels.values()) == {"fine"}
        aim_at_head(renderer, face, "front")
        assert np.array_equal(renderer.render(*open_mouth), far)
    whole, _ = _render(face, open_mouth, (640, 480), detail=False, close_up=True)
    assert np.abs(whole.astype(int) - near.astype(int)).max() <= 1


@settings(max_examples=40, deadline=None)
@given(distance=st.floats(1.0, 400.0), height=st.integers(60, 2160), fov=st.floats(10.0, 90.0))
def test_a_part_is_coarse_exactly_when_its_edges_would_be_drawn_small(detail, distance, height, fov):
    eye = np.array([0.0, 0.0, distance])
    levels = detail.levels(eye, np.array([0.0, 0.0, 1.0]), fov, height)
    focal = height / (2 * np.tan(np.radians(fov) / 2))
    for name, part in detail.parts.items():
        depth = distance - part.centre[2]
        assert (levels[name] == "coarse") == (depth > 0 and part.edge * focal / depth < FINE_EDGE_PX)
    farther = detail.levels(2 * eye, np.array([0.0, 0.0, 1.0]), fov, height)
    assert all(farther[name] == "coarse" for name, level in levels.items() if level == "coarse")
