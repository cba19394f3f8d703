"""Where a frame's normals are best summed, on this GL: on the CPU (numpy, ``VertexNormals``,
uploaded with the positions) or in the draw (``Renderer(gpu_normals=True)``: the vertex shader
sums each vertex's ring, positions alone uploaded). For the default face and it subdivided once
and twice (10k, 23k, 75k vertices), a frame of the smooth take ``puppet bench`` deforms, both
ways in turns: the CPU's deform (+ normals) in this thread's CPU time, the whole frame (deform,
upload, draw, read-back of a 640x480 image) in wall time and in the process's CPU time (the
rasteriser's threads included). Medians. On a software rasteriser the draw's vertex shader runs
on the CPU too, which is why ``choose_normals`` keeps normals on the CPU there; on a GPU run it to
see what summing in the draw gives.

    OPENBLAS_NUM_THREADS=1 python tools/bench/normals_draw.py [--frames 60] [--no-subdivided]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from puppet.bench.deform import smooth_take
from puppet.face.load import load_face
from puppet.face.subdivide import subdivide
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer
from puppet.view.rendertake import aim_at_head


def _medians(frame, frames: int) -> tuple[float, float, float]:
    """Median (deform CPU ms of this thread, frame wall ms, frame process CPU ms) of ``frame(i)``,
    which returns its deform's thread CPU seconds."""
    frame(0)
    deform, wall, cpu = [], [], []
    for i in range(frames):
        w, c = time.perf_counter(), time.process_time()
        deform.append(frame(i))
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    return tuple(1e3 * statistics.median(x) for x in (deform, wall, cpu))


def measure(mesh, frames: int, rounds: int = 3) -> dict[str, tuple[float, float, float]]:
    """Both ways of one mesh, ``rounds`` turns each (see the module docstring)."""
    runtime = Runtime(mesh)
    d, motions = smooth_take(runtime, frames, np.random.default_rng(7))
    out, normals = np.empty_like(runtime.rest), np.empty_like(runtime.rest)
    renderers = {gpu: Renderer.for_face(mesh, width=640, height=480, gpu_normals=gpu) for gpu in (False, True)}
    for renderer in renderers.values():
        aim_at_head(renderer, mesh, "front")

    def on_cpu(i: int) -> float:
        start = time.thread_time()
        runtime.deform_with_normals(d[i % frames], motions[i % frames], out=out, normals_out=normals)
        spent = time.thread_time() - start
        renderers[False].render(out, normals)
        return spent

    def in_draw(i: int) -> float:
        start = time.thread_time()
        runtime.deform(d[i % frames], motions[i % frames], out=out)
        spent = time.thread_time() - start
        renderers[True].render(out)
        return spent

    results: dict[str, list] = {"normals on the CPU": [], "normals in the draw": []}
    try:
        for _ in range(rounds):
            results["normals on the CPU"].append(_medians(on_cpu, frames))
            results["normals in the draw"].append(_medians(in_draw, frames))
    finally:
        for renderer in renderers.values():
            renderer.release()
    return {way: tuple(statistics.median(r[k] for r in runs) for k in range(3)) for way, runs in results.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--no-subdivided", action="store_true")
    args = parser.parse_args()
    face = load_face()
    with Renderer.for_face(face, width=64, height=48) as probe:
        print(f"GL: {probe.ctx.info['GL_RENDERER']}; normals in the draw by default: {probe.gpu_normals}")
    print(f"{'vertices':>8}  {'way':20} {'deform CPU ms':>13} {'frame wall ms':>13} {'frame CPU ms':>12}")
    for times in (0, 1, 2) if not args.no_subdivided else (0,):
        mesh = subdivide(face, times) if times else face
        for way, (deform, wall, cpu) in measure(mesh, args.frames).items():
            print(f"{len(mesh.vertices):8d}  {way:20} {deform:13.3f} {wall:13.2f} {cpu:12.2f}")


if __name__ == "__main__":
    main()
