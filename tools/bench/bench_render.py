"""Median milliseconds per rendered frame (draw + RGB read-back) of the default face, for the
renderer as it was (``--old-rev``'s renderer module, loaded from git: the studio shader, 4x MSAA
by default), as it was at ``--base-rev`` (its default for this GL), the renderer now (no AA, the
default for this GL, the default drawing both sides or every triangle of the eyeballs and teeth
(``Renderer.for_face(detail=False)``), 4x MSAA) and a minimal Lambert draw of every triangle
without MSAA (the floor). Configurations take turns, a few frames each, so a load
that comes and goes on a shared machine hits them alike. The CPU column is the process's CPU
time a frame, the software rasteriser's threads included: on a busy machine it moves less than
the wall time, and on an idle one, wall >= CPU / cores.

    python tools/bench/bench_render.py [--size 640x480] [--rounds 15] [--old-rev e3b5562] [--base-rev main]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import moderngl
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.view import renderer as render
from puppet.view.rendertake import aim_at_head

_LAMBERT_VS = """
#version 330
uniform mat4 view_projection;
in vec3 in_position;
in vec3 in_normal;
out vec3 v_normal;
void main() {
    v_normal = in_normal;
    gl_Position = view_projection * vec4(in_position, 1.0);
}
"""
_LAMBERT_FS = """
#version 330
in vec3 v_normal;
out vec4 f_color;
void main() {
    f_color = vec4(vec3(max(dot(normalize(v_normal), vec3(0.0, 0.0, 1.0)), 0.0)), 1.0);
}
"""


class Lambert:
    """The floor: positions + normals, one directional light, no MSAA, RGBA read-back."""

    def __init__(self, face, size: tuple[int, int], view_projection: np.ndarray) -> None:
        self.ctx = moderngl.create_context(standalone=True, backend="egl")
        self.program = self.ctx.program(vertex_shader=_LAMBERT_VS, fragment_shader=_LAMBERT_FS)
        self.program["view_projection"].write(np.ascontiguousarray(view_projection.T, dtype="f4"))
        self.buffer = self.ctx.buffer(reserve=len(face.vertices) * 24, dynamic=True)
        indices = self.ctx.buffer(np.ascontiguousarray(face.triangles, dtype="u4"))
        self.vao = self.ctx.vertex_array(self.program, [(self.buffer, "3f 3f", "in_position", "in_normal")],
                                         index_buffer=indices, index_element_size=4)
        self.fbo = self.ctx.framebuffer([self.ctx.renderbuffer(size, 4)], self.ctx.depth_renderbuffer(size))
        self.staging = np.empty((len(face.vertices), 6), dtype="f4")

    def render(self, vertices: np.ndarray, normals: np.ndarray) -> bytes:
        with self.ctx:
            return self._render(vertices, normals)

    def _render(self, vertices: np.ndarray, normals: np.ndarray) -> bytes:
        self.staging[:, :3], self.staging[:, 3:] = vertices, normals
        self.buffer.write(self.staging)
        self.fbo.use()
        self.fbo.clear(depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.vao.render(moderngl.TRIANGLES)
        return self.fbo.read(components=4)

    def release(self) -> None:
        self.ctx.release()


def old_render_module(rev: str, name: str = "old_render"):
    """The renderer as it was at ``rev`` (puppet/view/renderer.py, or puppet/render.py before the
    package was layered, its one import of ours moved to where it lives now), imported under
    another name."""
    for where in ("puppet/view/renderer.py", "puppet/render.py"):
        shown = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{where}"], capture_output=True, text=True)
        if shown.returncode == 0:
            break
    shown.check_returncode()
    source = shown.stdout.replace("from puppet.normals import", "from puppet.runtime.normals import")  # issue 16's move
    path = Path(tempfile.mkdtemp()) / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="640x480")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--frames", type=int, default=4, help="frames per configuration per round")
    parser.add_argument("--old-rev", default="e3b5562", help="the commit whose render.py is 'old'")
    parser.add_argument("--base-rev", default="main", help="a commit whose default renderer to compare with")
    args = parser.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))
    face = load_face()
    runtime = Runtime(face)
    frames = [runtime.deform_with_normals(*runtime.fap_controls(expression=(1, 63, 0, 0)))
              for _ in range(1)] + [runtime.deform_with_normals(*runtime.fap_controls())]
    old = old_render_module(args.old_rev)
    base = old_render_module(args.base_rev, "base_render")
    options = {"width": size[0], "height": size[1]}
    renderers = {
        "old default (studio shader, 4x MSAA)": old.Renderer.for_face(face, samples=4, **options),
        "old, no MSAA": old.Renderer.for_face(face, samples=0, **options),
        f"{args.base_rev}'s default": base.Renderer.for_face(face, **options),
        "new, 4x MSAA (a GPU's default)": render.Renderer.for_face(face, samples=4, **options),
        "new, no antialiasing": render.Renderer.for_face(face, samples=0, antialias="none", **options),
        "new default, both sides drawn": render.Renderer.for_face(face, cull=False, **options),
        "new, lit per pixel, FXAA pass": render.Renderer.for_face(face, shading="pixel", antialias="fxaa", **options),
        "new default, every triangle drawn": render.Renderer.for_face(face, detail=False, **options),
    }
    new_default = render.Renderer.for_face(face, **options)
    renderers[f"new default ({new_default.samples}x MSAA, {new_default.antialias}, lit per {new_default.shading})"] = new_default
    aim_at_head(new_default, face, "front")
    camera = new_default.camera
    for r in renderers.values():  # the old renderers' camera has the same look_at, not aim
        r.look_at(camera.eye, camera.target, camera.up, camera.fov, camera.near, camera.far)
    view_projection = new_default._view_projection()
    lambert = Lambert(face, size, view_projection)
    runs = {name: r.render for name, r in renderers.items()}
    runs["minimal Lambert, no MSAA (floor)"] = lambert.render
    times: dict[str, list[float]] = {name: [] for name in runs}
    cpu: dict[str, list[float]] = {name: [] for name in runs}
    for name, run in runs.items():  # warm up: shader compilation, first uploads
        run(*frames[0])
    for _ in range(args.rounds):
        for name, run in runs.items():
            for k in range(args.frames):
                vertices, normals = frames[k % len(frames)]
                start, start_cpu = time.perf_counter(), time.process_time()
                run(vertices, normals)
                times[name].append((time.perf_counter() - start) * 1e3)
                cpu[name].append((time.process_time() - start_cpu) * 1e3)
    gl = new_default.ctx.info["GL_RENDERER"]
    floor = statistics.median(times["minimal Lambert, no MSAA (floor)"])
    print(f"{gl}, {size[0]}x{size[1]}, {len(face.triangles)} triangles, "
          f"{args.rounds * args.frames} frames each, load average {' '.join(open('/proc/loadavg').read().split()[:3])}")
    print(f"{'configuration':<40} {'median ms':>10} {'p90 ms':>8} {'x floor':>8} {'CPU ms':>8}")
    for name, values in times.items():
        median = statistics.median(values)
        p90 = float(np.percentile(values, 90))
        print(f"{name:<40} {median:>10.2f} {p90:>8.2f} {median / floor:>8.2f} {statistics.median(cpu[name]):>8.2f}")
    for r in renderers.values():
        r.release()
    lambert.release()


if __name__ == "__main__":
    main()
