"""The cheap default renderer keeps the studio look: images of the default face drawn the old
way (one shader sampling a 1x1 white texture, 4x MSAA, lit per pixel) and the new way (the
untextured variant, the default antialiasing and shading for this GL) differ by under 2/255 on
average; lit per vertex and per pixel, by under a fifth of a level."""

from __future__ import annotations

import moderngl
import numpy as np
import pytest

from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.view import renderer as render
from puppet.view.rendertake import aim_at_head

SIZE = (320, 240)
POSES = {"neutral": {}, "joy": {"expression": (1, 63, 0, 0)}}


def studio_4x(face, **size) -> render.Renderer:
    """The renderer as it was: the textured shader on a white texel of weight 0, 4x MSAA."""
    n = len(face.vertices)
    white = np.full((1, 1, 3), 255, dtype=np.uint8)
    return render.Renderer(face.triangles, n, face.colors, uv=np.zeros((n, 2)), texture=white,
                           texture_weight=np.zeros(n), samples=4, antialias="none", **size)


@pytest.fixture(scope="module")
def face_and_poses():
    face = load_face()
    runtime = Runtime(face)
    return face, {name: runtime.deform_faps(**kwargs) for name, kwargs in POSES.items()}


def _images(renderer: render.Renderer, face, poses: dict) -> dict:
    with renderer:
        aim_at_head(renderer, face, "front")
        return {name: renderer.render(vertices) for name, vertices in poses.items()}


@pytest.fixture(scope="module")
def old_and_new(face_and_poses, egl):
    face, poses = face_and_poses
    old = _images(studio_4x(face, width=SIZE[0], height=SIZE[1]), face, poses)
    new = _images(render.Renderer.for_face(face, width=SIZE[0], height=SIZE[1]), face, poses)
    return old, new


def smooth_pixels(image: np.ndarray, contrast: int = 6) -> np.ndarray:
    """Mask of pixels whose 3x3 neighbourhood spans under ``contrast`` levels in every channel:
    away from edges, where antialiasing has nothing to do and shading alone sets the colour."""
    padded = np.pad(image.astype(int), ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = image.shape[:2]
    windows = np.stack([padded[i:i + h, j:j + w] for i in range(3) for j in range(3)])
    return np.all(windows.max(axis=0) - windows.min(axis=0) < contrast, axis=2)


def shading_differs(old: np.ndarray, new: np.ndarray) -> float:
    """The share of smooth pixels (``smooth_pixels`` of ``old``) that differ by over 2 levels."""
    smooth = smooth_pixels(old)
    return float((np.abs(old.astype(int) - new.astype(int)).max(axis=2)[smooth] > 2).mean())


@pytest.mark.parametrize("pose", list(POSES))
def test_default_renderer_keeps_the_studio_look(old_and_new, pose: str) -> None:
    old, new = old_and_new
    diff = np.abs(old[pose].astype(int) - new[pose].astype(int))
    assert diff.mean() < 2.0, diff.mean()  # antialiasing differs on edges, a few % of pixels
    assert shading_differs(old[pose], new[pose]) < 0.001  # the shading itself is the same


def test_a_misdrawn_face_fails_the_bound(old_and_new, face_and_poses) -> None:
    """The check can fail: the studio shader without its specular sheen changes the shading."""
    old, _ = old_and_new
    face, poses = face_and_poses
    dull = render.Renderer(face.triangles, len(face.vertices), face.colors, materials=np.zeros(len(face.vertices)),
                           width=SIZE[0], height=SIZE[1])
    image = _images(dull, face, poses)["neutral"]
    assert shading_differs(old["neutral"], image) > 0.01


def test_fxaa_smooths_a_hard_edge_and_leaves_flat_areas_alone(face_and_poses, egl) -> None:
    face, poses = face_and_poses
    plain = _images(render.Renderer.for_face(face, width=SIZE[0], height=SIZE[1], samples=0,
                                             antialias="none"), face, poses)["neutral"]
    fxaa = _images(render.Renderer.for_face(face, width=SIZE[0], height=SIZE[1], samples=0,
                                            antialias="fxaa"), face, poses)["neutral"]
    changed = np.any(plain != fxaa, axis=2)
    assert 0 < changed.mean() < 0.1  # some edge pixels, a small part of the image
    corner = (slice(0, 20), slice(0, 20))  # the smooth background gradient
    assert np.array_equal(plain[corner], fxaa[corner])


def test_defaults_follow_the_rasteriser(egl_context) -> None:
    ctx = egl_context
    samples, antialias = render.choose_antialias(ctx)
    if render.software_rasteriser(ctx):
        assert (samples, antialias) == (0, "none")
    else:
        assert samples > 1 and antialias == "none"
    assert render.choose_antialias(ctx, samples=0, antialias="none") == (0, "none")
    assert render.choose_antialias(ctx, antialias="fxaa")[0] == 0
    with pytest.raises(ValueError, match="antialias 'smaa'"):
        render.choose_antialias(ctx, antialias="smaa")


def test_a_window_framebuffer_gets_the_offscreen_image(face_and_poses, old_and_new) -> None:
    """What the live window draws (a borrowed context, its own framebuffer) is what an
    offscreen render of the same frame returns: the same defaults, the same passes."""
    face, poses = face_and_poses
    _, new = old_and_new
    ctx = moderngl.create_context(standalone=True, backend="egl")
    with ctx:
        screen = ctx.simple_framebuffer(SIZE)
        renderer = render.Renderer.for_face(face, width=SIZE[0], height=SIZE[1], ctx=ctx)
        aim_at_head(renderer, face, "front")
        renderer.draw(poses["joy"], framebuffer=screen)
        data = screen.read(components=3, alignment=1)
        renderer.release()
    image = np.frombuffer(data, dtype=np.uint8).reshape(SIZE[1], SIZE[0], 3)[::-1]
    assert np.array_equal(image, new["joy"])


def test_culling_back_faces_changes_a_wide_open_mouth_by_a_few_pixels(face_and_poses, egl) -> None:
    """Back faces show only where the skin folds over at the corners of a wide open mouth: the
    culled image (the default) and the two-sided one differ in under 0.1% of the pixels."""
    face, _ = face_and_poses
    runtime = Runtime(face)
    poses = {"open": runtime.deform_faps({"open_jaw": 1000}), "open_smile": runtime.deform_faps({"open_jaw": 700}, expression=(1, 63, 0, 0))}
    size = {"width": SIZE[0], "height": SIZE[1]}
    culled = _images(render.Renderer.for_face(face, shading="pixel", **size), face, poses)
    both = _images(render.Renderer.for_face(face, cull=False, **size), face, poses)
    for name in poses:
        differ = np.any(culled[name] != both[name], axis=2)
        assert differ.mean() < 0.001, (name, int(differ.sum()))


def _lit_both_ways(face, poses: dict, **options) -> tuple[dict, dict]:
    size = {"width": SIZE[0], "height": SIZE[1]}
    return tuple(_images(render.Renderer.for_face(face, shading=shading, **size, **options), face, poses)
                 for shading in ("pixel", "vertex"))


def test_lighting_per_vertex_keeps_the_look(face_and_poses, egl) -> None:
    """Per vertex (a software rasteriser's default) against per pixel: the same face, the
    colour of a few pixels' sheen on the lips and teeth apart."""
    face, poses = face_and_poses
    pixel, vertex = _lit_both_ways(face, poses)
    for pose in poses:
        diff = np.abs(pixel[pose].astype(int) - vertex[pose].astype(int))
        assert 0 < diff.mean() < 0.25, (pose, diff.mean())
        assert shading_differs(pixel[pose], vertex[pose]) < 0.01


def test_a_textured_face_lit_per_vertex_keeps_its_texture(face_and_poses, egl) -> None:
    """The textured variant lit per vertex still samples the texture per pixel: stripes painted
    across the face show as sharply as lit per pixel."""
    face, poses = face_and_poses
    stripes = np.zeros((64, 64, 3), dtype=np.uint8)
    stripes[:, ::8] = stripes[:, 1::8] = 255
    uv = (face.vertices[:, :2] - face.vertices[:, :2].min(axis=0)) / np.ptp(face.vertices[:, :2], axis=0)
    options = {"uv": uv, "texture": stripes, "texture_weight": np.ones(len(uv))}
    size = {"width": SIZE[0], "height": SIZE[1]}
    pixel, vertex = (_images(render.Renderer(face.triangles, len(uv), face.colors, shading=shading, **options, **size),
                             face, poses) for shading in ("pixel", "vertex"))
    plain = _images(render.Renderer.for_face(face, shading="vertex", **size), face, poses)
    for pose in poses:
        assert np.abs(plain[pose].astype(int) - vertex[pose].astype(int)).mean() > 10  # the stripes show
        assert np.abs(pixel[pose].astype(int) - vertex[pose].astype(int)).mean() < 0.5


def test_shading_follows_the_rasteriser(egl_context) -> None:
    ctx = egl_context
    expected = "vertex" if render.software_rasteriser(ctx) else "pixel"
    assert render.choose_shading(ctx) == expected
    assert render.choose_shading(ctx, "pixel") == "pixel"
    assert render.choose_shading(ctx, "vertex", cull=False) == "pixel"  # a back face needs its own normal
    with pytest.raises(ValueError, match="shading 'flat'"):
        render.choose_shading(ctx, "flat")
