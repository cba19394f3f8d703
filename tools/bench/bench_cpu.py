"""The per-frame CPU work measured in CPU time, which other processes' load moves far less than
wall time: for comparing two checkouts on a shared machine (``puppet bench`` measures wall time,
right on a quiet one).

* frame work on the default face, median CPU ms of this thread: a FAP frame (controls + deform),
  every muscle at 0.5 (controls + deform; then + normals), every muscle swinging 0.45-0.55 with
  the jaw working (+ normals), the zygomatic pair at 3, both upper lids blinking (496-1024 IRISD:
  the sliver guard's range), and the poses of one whole cycle of the latency run's slider box,
  frame after frame (``puppet.bench.pipeline.box_poses``: its mapping, muscles and guards);
* deform and deform + normals of the smooth take ``puppet bench`` uses, on the default face and
  it subdivided once and twice (10k, 23k, 75k vertices; ``--no-subdivided`` skips those).

    OPENBLAS_NUM_THREADS=1 python tools/bench/bench_cpu.py [--tree DIR] [--no-subdivided]

``--tree`` measures another checkout's ``puppet`` (e.g. ``git worktree add /tmp/main main``).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path


def cpu_ms(frame, frames: int) -> float:
    """Median CPU ms of this thread over ``frames`` calls of ``frame(i)``, after a warm-up."""
    frame(0)
    times = []
    for i in range(frames):
        start = time.thread_time()
        frame(i)
        times.append(time.thread_time() - start)
    return 1e3 * statistics.median(times)


def frame_work(frames: int) -> None:
    import numpy as np

    import puppet
    from puppet.bench.pipeline import box_poses

    runtime = puppet.Runtime(puppet.load_face())
    fap = np.zeros(68)
    fap[[2, 11, 12]] = 200.0, 60.0, 60.0
    every = dict.fromkeys(runtime.muscle_names, 0.5)
    out, normals = np.empty_like(runtime.rest), np.empty_like(runtime.rest)

    def moving(i: int) -> None:
        swing = np.sin(i / 15)
        values = fap.copy()
        values[2] = 200 + 50 * swing
        muscles = dict.fromkeys(runtime.muscle_names, 0.5 + 0.05 * swing)
        runtime.deform_with_normals(*runtime.fap_controls(values), muscles=muscles, out=out, normals_out=normals)

    def blinking(i: int) -> None:
        values = np.zeros(68)
        values[[18, 19]] = 760 + 264 * np.sin(i / 10)
        runtime.deform_faps(values, out=out)

    poses = box_poses()

    def box(i: int) -> None:
        runtime.deform_pose(poses[i % len(poses)], out=out, normals_out=normals)

    cases = {
        "FAP frame: controls + deform": lambda i: runtime.deform(*runtime.fap_controls(fap), out=out),
        "every muscle 0.5: controls + deform": lambda i: runtime.deform_faps(fap, muscles=every, out=out),
        "every muscle 0.5: controls + deform + normals": lambda i: runtime.deform_with_normals(
            *runtime.fap_controls(fap), muscles=every, out=out, normals_out=normals),
        "every muscle 0.45-0.55 moving, jaw working: + normals": moving,
        "zygomatic pair at 3: controls + deform": lambda i: runtime.deform_faps(
            fap, muscles={"zygomatic_major_l": 3.0, "zygomatic_major_r": 3.0}, out=out),
        "a blink swinging 496-1024 IRISD: controls + deform": blinking,
    }
    for name, frame in cases.items():
        print(f"{name:55s} {cpu_ms(frame, frames):7.3f} ms CPU")
    print(f"{'the slider box, one cycle (the latency run): + normals':55s} {cpu_ms(box, len(poses)):7.3f} ms CPU")


def scaling(frames: int, subdivided: bool) -> None:
    import numpy as np

    import puppet
    from puppet.bench.deform import smooth_take
    from puppet.face.subdivide import subdivide

    face = puppet.load_face()
    for times in (0, 1, 2) if subdivided else (0,):
        mesh = subdivide(face, times) if times else face
        runtime = puppet.Runtime(mesh)
        d, motions = smooth_take(runtime, frames, np.random.default_rng(7))
        out, normals = np.empty_like(runtime.rest), np.empty_like(runtime.rest)
        positions = cpu_ms(lambda i: runtime.deform(d[i % frames], motions[i % frames], out=out), frames)
        both = cpu_ms(lambda i: runtime.deform_with_normals(d[i % frames], motions[i % frames], out=out,
                                                            normals_out=normals), frames)
        print(f"{len(mesh.vertices):6d} vertices, {runtime.B.nnz:7d} entries in B: deform {positions:6.3f} ms, "
              f"deform + normals {both:6.3f} ms CPU")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=Path(__file__).resolve().parents[2],
                        help="the checkout whose puppet to measure (default: this one)")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--no-subdivided", action="store_true")
    args = parser.parse_args()
    sys.path.insert(0, str(args.tree.resolve()))
    import puppet

    print(f"puppet from {Path(puppet.__file__).parent}")
    frame_work(args.frames)
    scaling(min(args.frames, 120), not args.no_subdivided)


if __name__ == "__main__":
    main()
