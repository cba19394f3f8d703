"""Tests of the offscreen renderer on an icosphere, with a headless EGL context only."""

from __future__ import annotations

from types import SimpleNamespace

import imageio.v2 as imageio
import numpy as np
import pytest
import trimesh
from PIL import Image

from puppet.runtime.normals import VertexNormals
from puppet.view.renderer import VIEW_DIRECTIONS, Renderer, render_face, save_png, write_video

WIDTH, HEIGHT = 192, 160
CENTRE = np.array([0.0, 7.2, 1.0])


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    mesh = trimesh.creation.icosphere(subdivisions=3)
    return trimesh.Trimesh(mesh.vertices + CENTRE, mesh.faces, process=False)


@pytest.fixture(scope="module")
def renderer(egl: None, sphere: trimesh.Trimesh):
    with Renderer(sphere.faces, len(sphere.vertices), width=WIDTH, height=HEIGHT) as r:
        r.aim(sphere.vertices)
        yield r


def _is_grey(pixel: np.ndarray) -> bool:
    return int(pixel.max()) - int(pixel.min()) < 12


def test_image_covers_centre_not_corners(renderer: Renderer, sphere: trimesh.Trimesh) -> None:
    image = renderer.render(sphere.vertices)
    assert image.shape == (HEIGHT, WIDTH, 3)
    assert image.dtype == np.uint8
    centre = image[HEIGHT // 2, WIDTH // 2]
    assert int(centre[0]) - int(centre[2]) > 30  # skin tone, not grey
    for corner in (image[0, 0], image[0, -1], image[-1, 0], image[-1, -1]):
        assert _is_grey(corner)


def test_deformation_changes_only_its_image_region(
    renderer: Renderer, sphere: trimesh.Trimesh
) -> None:
    rest = np.asarray(sphere.vertices, dtype=float)
    before = renderer.render(rest)
    moved = np.linalg.norm(rest - (CENTRE + [0.45, 0.3, 0.84]), axis=1) < 0.25
    deformed = rest.copy()
    deformed[moved] += 0.15 * (rest[moved] - CENTRE)
    after = renderer.render(deformed)

    # Moving a vertex changes its triangles and the normals of their vertices, which shade
    # every triangle touching those vertices: the change is confined to those triangles.
    faces = np.asarray(sphere.faces)
    ring = np.unique(faces[moved[faces].any(axis=1)])
    touched = np.unique(faces[np.isin(faces, ring).any(axis=1)])
    corners = renderer.project(np.concatenate([rest[touched], deformed[touched]]))
    (x0, y0), (x1, y1) = np.floor(corners.min(axis=0)) - 2, np.ceil(corners.max(axis=0)) + 2

    changed = np.any(before != after, axis=2)
    rows, cols = np.nonzero(changed)
    assert len(rows) > 0
    assert x0 <= cols.min() and cols.max() <= x1
    assert y0 <= rows.min() and rows.max() <= y1
    assert (x1 - x0) * (y1 - y0) < 0.3 * WIDTH * HEIGHT  # the region is genuinely local


def test_same_input_renders_identically(renderer: Renderer, sphere: trimesh.Trimesh) -> None:
    vertices = np.asarray(sphere.vertices, dtype=float)
    normals = VertexNormals(sphere.faces, len(vertices))(vertices)
    first = renderer.render(vertices)
    np.testing.assert_array_equal(first, renderer.render(vertices))
    np.testing.assert_array_equal(first, renderer.render(vertices, normals))


@pytest.mark.usefixtures("egl")
@pytest.mark.parametrize("view", sorted(VIEW_DIRECTIONS))
def test_views_aim_at_the_object(view: str, sphere: trimesh.Trimesh, egl) -> None:
    mesh = trimesh.Trimesh(sphere.vertices * [0.8, 1.0, 0.9], sphere.faces, process=False)
    with Renderer(mesh.faces, len(mesh.vertices), width=WIDTH, height=HEIGHT) as r:
        r.aim(mesh.vertices, view=view)
        image = r.render(mesh.vertices)
        projected = r.project(mesh.vertices)
    assert not _is_grey(image[HEIGHT // 2, WIDTH // 2])
    assert projected.min() >= 0 and np.all(projected.max(axis=0) <= [WIDTH, HEIGHT])
    assert np.ptp(projected[:, 1]) > 0.7 * HEIGHT  # fitted, not lost in the distance


def test_look_at_from_behind(renderer: Renderer, sphere: trimesh.Trimesh) -> None:
    renderer.look_at(CENTRE - [0.0, 0.0, 6.0], CENTRE, fov=30.0)
    try:
        image = renderer.render(sphere.vertices)
    finally:
        renderer.aim(sphere.vertices)
    assert not _is_grey(image[HEIGHT // 2, WIDTH // 2])
    assert _is_grey(image[0, 0])


def test_a_moved_camera_is_drawn_from_where_it_now_is(renderer: Renderer, sphere: trimesh.Trimesh) -> None:
    """The camera's uniforms are written only when the camera changes: each frame after a move
    (and after moving back) equals a fresh renderer's from that camera."""
    front = renderer.camera
    side = Renderer(sphere.faces, len(sphere.vertices), width=WIDTH, height=HEIGHT)
    try:
        images = []
        for eye in (CENTRE + [4.0, 1.0, 3.0], front.eye):
            renderer.look_at(eye, CENTRE, fov=front.fov)
            side.look_at(eye, CENTRE, fov=front.fov)
            images.append(renderer.render(sphere.vertices))
            assert np.array_equal(images[-1], renderer.render(sphere.vertices))  # a frame with the camera held
            assert np.array_equal(images[-1], side.render(sphere.vertices))
        assert np.abs(images[0].astype(int) - images[1]).max() > 100
    finally:
        side.release()
        renderer.camera = front


def test_existing_context_is_used_and_kept(sphere: trimesh.Trimesh, egl_context) -> None:
    ctx = egl_context
    with Renderer(sphere.faces, len(sphere.vertices), width=64, height=64, ctx=ctx) as r:
        assert r.ctx is ctx
        assert r.render(sphere.vertices).shape == (64, 64, 3)
    ctx.buffer(reserve=16).release()  # still alive after the renderer is released


def test_wrong_vertex_count_is_rejected(renderer: Renderer, sphere: trimesh.Trimesh) -> None:
    with pytest.raises(ValueError):
        renderer.render(sphere.vertices[:-1])


@pytest.mark.usefixtures("egl")
def test_render_face_one_shot(sphere: trimesh.Trimesh, egl) -> None:
    face = SimpleNamespace(vertices=sphere.vertices, triangles=sphere.faces, colors=None)
    image = render_face(face, view="three_quarter", width=64, height=48)
    assert image.shape == (48, 64, 3)
    assert not _is_grey(image[24, 32])


def test_save_png_round_trips(renderer: Renderer, sphere: trimesh.Trimesh, tmp_path) -> None:
    image = renderer.render(sphere.vertices)
    save_png(image, tmp_path / "frame.png")
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "frame.png")), image)


def test_video_is_written_and_readable(
    renderer: Renderer, sphere: trimesh.Trimesh, tmp_path
) -> None:
    rest = np.asarray(sphere.vertices, dtype=float)
    frames = (renderer.render(CENTRE + (rest - CENTRE) * (1 + 0.05 * k)) for k in range(5))
    path = tmp_path / "take.mp4"
    assert write_video(frames, path, fps=25) == 5
    with imageio.get_reader(path) as reader:
        read = list(reader.iter_data())
    assert len(read) == 5
    assert read[0].shape == (HEIGHT, WIDTH, 3)


def test_video_pads_odd_sizes(tmp_path) -> None:
    frames = [np.full((33, 47, 3), 100 + 20 * k, dtype=np.uint8) for k in range(3)]
    path = tmp_path / "odd.mp4"
    assert write_video(frames, path, fps=10) == 3
    with imageio.get_reader(path) as reader:
        read = list(reader.iter_data())
    assert len(read) == 3
    assert read[0].shape == (34, 48, 3)


def test_renderers_with_own_contexts_coexist(renderer: Renderer, sphere: trimesh.Trimesh) -> None:
    first = renderer.render(sphere.vertices)
    with Renderer(sphere.faces, len(sphere.vertices), width=32, height=32) as other:
        other.render(sphere.vertices)
        np.testing.assert_array_equal(renderer.render(sphere.vertices), first)
    np.testing.assert_array_equal(renderer.render(sphere.vertices), first)


def test_drawing_through_ctypes_draws_what_moderngl_draws(renderer: Renderer, sphere: trimesh.Trimesh,
                                                          monkeypatch) -> None:
    """The draw call and the wait go through the GL library with ctypes (the GIL let go); where
    no GL library is found moderngl makes them: the same image either way."""
    from puppet.view import renderer as render

    assert render._gl_library() is not None  # this machine has one: the ctypes path is the one tested
    vertices = CENTRE + (sphere.vertices - CENTRE) * [1.2, 0.9, 1.0]
    through_ctypes = renderer.render(vertices)
    monkeypatch.setattr(render, "_gl_library", lambda: None)
    np.testing.assert_array_equal(renderer.render(vertices), through_ctypes)


def test_other_threads_run_while_the_mesh_is_drawn(egl: None, monkeypatch) -> None:
    """A device's reader thread is not held up by the draw call, where a software rasteriser
    transforms, lights and bins the mesh on the calling thread: it runs during the call. With
    moderngl's call (no GL library found) it cannot (the GIL is held throughout)."""
    import sys
    import threading

    from puppet.view import renderer as render

    mesh = trimesh.creation.icosphere(subdivisions=6)  # 82k triangles: milliseconds of draw call
    with Renderer(mesh.faces, len(mesh.vertices), width=64, height=64) as r:
        r.aim(mesh.vertices)
        r.render(mesh.vertices, mesh.vertex_normals)

        def counted_during_draw() -> int:
            count, running, stop = [0], threading.Event(), threading.Event()

            def count_up() -> None:
                running.set()
                while not stop.is_set():
                    count[0] += 1

            thread = threading.Thread(target=count_up)
            thread.start()
            running.wait()  # the counter has run; this thread holds the GIL again from here
            with r._current():
                before = count[0]
                render.draw_triangles(r._mesh)
                during = count[0] - before
                render.wait_for_gl(r.ctx)
            stop.set()
            thread.join()
            return during

        interval = sys.getswitchinterval()
        sys.setswitchinterval(0.05)  # the counter could take the GIL only after 50 ms of waiting
        try:
            assert counted_during_draw() > 0
            monkeypatch.setattr(render, "_gl_library", lambda: None)
            sys.setswitchinterval(0.5)  # a draw slowed past 50 ms by a busy machine still holds it
            assert counted_during_draw() == 0
        finally:
            sys.setswitchinterval(interval)
