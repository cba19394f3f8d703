"""Normals summed in the draw: the vertex rings give the CPU's normals, a renderer that sums them
draws the same face, a GL that cannot is told so, and the live loop then computes none."""

from __future__ import annotations

import time
from pathlib import Path
from types import SimpleNamespace

import moderngl
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_session import JOYSTICK, MAPPING

import puppet
from devices import State, open_device
from puppet.fap.pose import Pose
from puppet.live.session import LiveSession
from puppet.runtime.normals import VertexNormals, vertex_rings
from puppet.view.renderer import Renderer, choose_normals, gpu_normals_supported
from puppet.view.rendertake import aim_at_head


def _ring_sums(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex, the sum over ``vertex_rings`` of the corner's cross products (as the shader
    sums them) and the sum of their lengths."""
    starts, others = vertex_rings(triangles, len(vertices))
    owner = np.repeat(np.arange(len(vertices)), np.diff(starts.astype(np.int64)))
    x = vertices[owner]
    crosses = np.cross(vertices[others[:, 0]] - x, vertices[others[:, 1]] - x)
    sums, lengths = np.zeros_like(vertices), np.zeros(len(vertices))
    np.add.at(sums, owner, crosses)
    np.add.at(lengths, owner, np.linalg.norm(crosses, axis=1))
    return sums, lengths


def _ring_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    sums, _ = _ring_sums(vertices, triangles)
    return sums / np.maximum(np.linalg.norm(sums, axis=1, keepdims=True), 1e-30)


@settings(max_examples=60, deadline=None)
@given(st.integers(4, 30).flatmap(lambda n: st.tuples(
    st.just(n),
    st.lists(st.lists(st.integers(0, n - 1), min_size=3, max_size=3, unique=True), min_size=1, max_size=60),
    st.integers(0, 2**32 - 1))))
def test_vertex_rings_sum_the_cpu_normals_of_any_mesh(case):
    n, triangles, seed = case
    triangles = np.array(triangles)
    vertices = np.random.default_rng(seed).normal(size=(n, 3))
    starts, _ = vertex_rings(triangles, n)
    assert starts[0] == 0 and starts[-1] == 3 * len(triangles) and np.all(np.diff(starts.astype(int)) >= 0)
    sums, lengths = _ring_sums(vertices, triangles)
    defined = np.linalg.norm(sums, axis=1) > 1e-9 * lengths  # not a ring whose triangles cancel out
    np.testing.assert_allclose(_ring_normals(vertices, triangles)[defined],
                               VertexNormals(triangles, n)(vertices)[defined], atol=1e-9)
    assert np.all(sums[lengths == 0] == 0)  # a vertex on no triangle has no normal either way


def test_vertex_rings_of_the_default_face(face):
    starts, others = vertex_rings(face.triangles, len(face.vertices))
    assert others.dtype == starts.dtype == np.uint32 and others.shape == (3 * len(face.triangles), 2)
    np.testing.assert_allclose(_ring_normals(face.vertices, face.triangles),
                               VertexNormals(face.triangles, len(face.vertices))(face.vertices), atol=1e-12)


@pytest.fixture(scope="module")
def posed(face, runtime):
    """The default face with the jaw open, a smile and the head turned: every part moved."""
    fap = np.zeros(68)
    fap[[2, 5, 6, 11, 12, 48]] = 600, 200, 200, 120, 120, 4000
    return runtime.deform_with_normals(*runtime.fap_controls(fap))


def _painted(face) -> dict:
    """A texture over the whole face (uv from x, y; a smooth colour ramp), as a face from a photo has."""
    x, y = face.vertices[:, 0], face.vertices[:, 1]
    uv = np.stack([(x - x.min()) / np.ptp(x), (y - y.min()) / np.ptp(y)], axis=1)
    ramp = np.linspace(0, 255, 64).astype(np.uint8)
    texture = np.stack(np.broadcast_arrays(ramp[None, :], ramp[:, None], np.uint8(128)), axis=-1)
    return {"uv": uv, "texture": np.ascontiguousarray(texture)}


@pytest.mark.parametrize("shading", ["vertex", "pixel"])
@pytest.mark.parametrize("textured", [False, True])
def test_a_renderer_summing_normals_in_the_draw_draws_the_face_the_cpu_normals_draw(face, posed, egl, shading,
                                                                                    textured):
    vertices, normals = posed
    paint = _painted(face) if textured else {}
    images = []
    for gpu in (False, True):
        with Renderer.for_face(face, width=320, height=240, shading=shading, gpu_normals=gpu, **paint) as renderer:
            assert renderer.gpu_normals is gpu
            aim_at_head(renderer, face, "three_quarter")
            images.append(renderer.render(vertices, normals).astype(int))
            if gpu:  # normals given to it are ignored: it sums its own
                np.testing.assert_array_equal(renderer.render(vertices, -normals), images[-1])
    cpu, gpu = images
    difference = np.abs(cpu - gpu)
    assert difference.mean() < 0.01 and difference.max() <= 2  # float32 sums against float64
    rest = Renderer.for_face(face, width=320, height=240, shading=shading, gpu_normals=True, **paint)
    with rest:
        aim_at_head(rest, face, "three_quarter")
        moved = np.abs(rest.render(face.vertices).astype(int) - gpu).max(axis=-1) > 8
    assert moved.sum() > 500  # the pose shows: the normals follow the positions, not the rest face


def test_this_machines_software_rasteriser_keeps_normals_on_the_cpu(egl_context):
    assert gpu_normals_supported(egl_context)  # llvmpipe: GL 4.5, storage blocks in vertex shaders
    assert choose_normals(egl_context) is False
    assert choose_normals(egl_context, True) is True


def _gl(renderer: str, version: int, blocks: int) -> SimpleNamespace:
    """What ``choose_normals`` reads of a context, for GLs this machine has not got."""
    info = {"GL_RENDERER": renderer, "GL_VERSION": f"{version // 100}.{version // 10 % 10}",
            "GL_MAX_VERTEX_SHADER_STORAGE_BLOCKS": blocks}
    return SimpleNamespace(info=info, version_code=version)


def test_a_gpu_sums_normals_where_its_gl_can_and_asking_where_it_cannot_says_why():
    assert choose_normals(_gl("NVIDIA H100 PCIe/PCIe/SSE2", 460, 16)) is True
    assert choose_normals(_gl("Apple M2", 410, 0)) is False
    assert choose_normals(_gl("Mali-G78", 430, 0)) is False  # GL 4.3 may give vertex shaders none
    with pytest.raises(ValueError, match=r"GL 4\.3.*4\.1 \(Apple M2\)"):
        choose_normals(_gl("Apple M2", 410, 0), True)


def test_a_live_session_without_normals_gives_the_same_vertices_and_none(runtime, tmp_path):
    device = open_device(JOYSTICK, "box")
    session = LiveSession(MAPPING, face=runtime, devices={"box": device}, record_root=tmp_path)
    session.mapping.idle = None  # a held pose holds still only without idle life (its blinks go on)
    try:
        deadline = time.monotonic() + 5
        while not (session.frame().states["box"] is State.OPEN and session.samples_fed):
            assert time.monotonic() < deadline, "the simulated box did not start"
            time.sleep(0.01)
        device.joystick.unplug()
        assert device.wait_state(State.LOST, 5.0)
        held = session.frame()
        with_normals = held.vertices.copy(), held.normals.copy()
        session.normals = False
        bare = session.frame()
        assert bare.normals is None
        np.testing.assert_array_equal(bare.vertices, with_normals[0])
        session.normals = True  # a held pose gets its normals back
        again = session.frame()
        np.testing.assert_array_equal(again.normals, with_normals[1])
    finally:
        session.close()


def test_a_pose_without_normals_has_the_same_positions(runtime):
    fap = np.zeros(68)
    fap[[2, 18, 48]] = 500.0, 700.0, 3000.0  # jaw, a lid, the head: the sliver guard and the turn
    pose = Pose(fap, muscles={runtime.muscle_names[0]: 0.5})
    vertices, _ = runtime.deform_pose(pose)
    alone, none = runtime.deform_pose(pose, normals=False)
    np.testing.assert_array_equal(alone, vertices)
    assert none is None


def test_a_take_played_without_normals_gives_the_same_vertices_and_none(face, runtime):
    from itertools import islice

    from puppet.view.rendertake import FapPlayback

    take = Path(puppet.__file__).parent / "data" / "demo_take.fap"
    playback = FapPlayback(take, face, runtime)
    with_normals = [v.copy() for v, _ in islice(playback, 40)]
    playback.normals = False
    bare = list(islice(playback, 40))
    assert all(n is None for _, n in bare)
    for (v, _), expected in zip(bare, with_normals):
        np.testing.assert_array_equal(v, expected)
    assert not np.array_equal(with_normals[0], with_normals[-1])  # the take moves the face


def test_a_driver_that_cannot_build_the_normals_shader_falls_back_to_the_cpu(face, posed, egl, monkeypatch):
    from puppet.view import renderer as render

    broken = render._MESH_VERTEX_SHADER.replace("#ifdef GPU_NORMALS\n", "#ifdef GPU_NORMALS\n#error no storage blocks here\n")
    monkeypatch.setattr(render, "_MESH_VERTEX_SHADER", broken)
    monkeypatch.setattr(render, "software_rasteriser", lambda ctx: False)  # chosen by default, as on a GPU
    with pytest.warns(RuntimeWarning, match="did not build; the CPU computes them"):
        renderer = Renderer.for_face(face, width=160, height=120)
    with renderer:
        assert renderer.gpu_normals is False
        aim_at_head(renderer, face, "front")
        image = renderer.render(*posed)
    assert image.std() > 10  # a face was drawn
    with pytest.raises(moderngl.Error, match="no storage blocks"):  # asked for outright: the driver's error
        Renderer.for_face(face, width=160, height=120, gpu_normals=True)


def test_the_latency_bench_with_normals_in_the_draw_computes_none_on_the_cpu(runtime, face, tmp_path, egl):
    from puppet.live.session import measure_latency

    session = LiveSession(MAPPING, face=runtime, devices={"box": open_device(JOYSTICK, "box")}, record_root=tmp_path)
    renderer = Renderer.for_face(face, width=160, height=120, gpu_normals=True)
    try:
        result = measure_latency(session, renderer, 0.5)
        assert result["normals"] == "draw" and result["samples"] > 0
        assert not session.normals and session.frame().normals is None
    finally:
        renderer.release()
        session.close()
