"""Rendered images of the deforming default face change where the motion is and nowhere else."""

from __future__ import annotations

import numpy as np
import pytest

from puppet.face import rigid
from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.view import renderer as render


@pytest.fixture(scope="module")
def scene(egl):
    face = load_face()
    runtime = Runtime(face)
    renderer = render.Renderer(face.triangles, len(face.vertices), face.colors, width=400, height=400)
    skin = face.vertices[face.parts["skin"]]
    renderer.aim(skin[skin[:, 1] > face.feature_points["2.1"][1] - 0.3], view="front")
    yield face, runtime, renderer
    renderer.release()


def _changed_box(renderer, before: np.ndarray, after: np.ndarray, margin: int = 3):
    moved = np.linalg.norm(after - before, axis=1) > 1e-6
    px = renderer.project(after[moved])
    px0 = renderer.project(before[moved])
    lo = np.minimum(px.min(axis=0), px0.min(axis=0)) - margin
    hi = np.maximum(px.max(axis=0), px0.max(axis=0)) + margin
    return moved, lo, hi


def test_a_smile_changes_pixels_around_the_mouth_and_nowhere_else(scene):
    face, runtime, renderer = scene
    d = np.zeros((len(runtime.control_points), 3))
    for name, move in {"8.3": (0.03, 0.03, 0), "2.4": (0.03, 0.03, 0)}.items():
        d[runtime.control_points.index(name)] = move
    neutral_v, neutral_n = runtime.deform_with_normals(np.zeros_like(d))
    smile_v, smile_n = runtime.deform_with_normals(d)
    neutral = renderer.render(neutral_v, neutral_n).astype(int)
    smile = renderer.render(smile_v, smile_n).astype(int)
    diff = np.abs(smile - neutral).max(axis=2) > 8
    assert diff.sum() > 200, "the smile did not show"
    _, lo, hi = _changed_box(renderer, neutral_v, smile_v)
    rows, cols = np.nonzero(diff)
    assert cols.min() >= lo[0] and cols.max() <= hi[0]
    assert rows.min() >= lo[1] and rows.max() <= hi[1]
    corner = renderer.project(face.vertices[[face.feature_vertices["8.3"]]])[0].astype(int)
    window = diff[corner[1] - 15:corner[1] + 15, corner[0] - 15:corner[0] + 15]
    assert window.any(), "nothing changed at the left lip corner"


def test_opening_the_jaw_shows_the_mouth_interior_not_the_background(scene):
    face, runtime, renderer = scene
    jaw = runtime.rig.rigid_parts["jaw"]
    d = np.zeros((len(runtime.control_points), 3))
    motion = {"jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, np.radians(14)))}
    image = renderer.render(*runtime.deform_with_normals(d, motion))
    closed = renderer.render(*runtime.deform_with_normals(d))
    mouth = (face.feature_points["2.2"] + face.feature_points["2.3"]) / 2
    col, row = renderer.project(mouth[None])[0].astype(int)
    background = image[5, 5].astype(int)
    inside = image[row - 2:row + 3, col - 2:col + 3].astype(int)
    assert np.abs(inside - background).max() > 30, "the open mouth shows the background"
    assert np.abs(inside.mean(axis=(0, 1)) - closed[row, col]).max() > 20, "the mouth did not open"


def _mouth_crop(renderer, face, image: np.ndarray) -> np.ndarray:
    corners = np.array([face.feature_points[p] for p in ("8.3", "8.4", "8.1", "2.1")])
    px = renderer.project(corners)
    lo = np.floor(px.min(axis=0)).astype(int) - 6
    hi = np.ceil(px.max(axis=0)).astype(int) + 6
    return image[lo[1]:hi[1], lo[0]:hi[0]].astype(int)


def test_visemes_and_expressions_render_visibly_different_mouths(scene):
    face, runtime, renderer = scene
    shapes = {
        "A": {"viseme": (10, 0, 63)}, "U": {"viseme": (14, 0, 63)}, "p/b/m": {"viseme": (1, 0, 63)},
        "joy": {"expression": (1, 63, 0, 0)}, "sadness": {"expression": (2, 63, 0, 0)},
    }
    crops = {}
    for name, high_level in shapes.items():
        d, motions = runtime.fap_controls(None, **high_level)
        crops[name] = _mouth_crop(renderer, face, renderer.render(*runtime.deform_with_normals(d, motions)))
    names = list(crops)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            changed = (np.abs(crops[a] - crops[b]).max(axis=2) > 12).mean()
            assert changed > 0.03, f"{a} and {b} look the same around the mouth ({changed:.1%} of pixels differ)"
