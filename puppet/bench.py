"""``puppet bench``: what the runtime costs, against a dense blendshape baseline, in one run.

For each mesh (the default face; it subdivided to about 4x and 16x the vertices; the ICT face when
``../shared/assets/ict_facekit`` is there) it measures, as medians:

* ``sibson_s``: computing every region's Sibson coordinates from scratch (no cache);
* ``load_s``: building the runtime from the on-disk coefficient cache;
* ``deform_ms`` and ``deform_normals_ms``: one frame of random control point displacements with
  a jaw rotation, positions only and positions + normals;
* ``dense_ms``: the same mesh and control points as dense blendshapes, one (V x 3) delta per
  control point (V x 3 x K, float32), one frame = rest + deltas @ weights; ``ratio`` is
  dense_ms / deform_ms.

Timings are single-threaded (BLAS limited to one thread before numpy loads) so they read as
"one core".
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from . import rigid  # noqa: E402
from .face import Face, load_face  # noqa: E402
from .runtime import Runtime  # noqa: E402
from .subdivide import subdivide  # noqa: E402


def median_time(fn: Callable[[], object], repeat: int) -> float:
    """Median wall time of ``fn`` in seconds over ``repeat`` calls (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def bench_face(face: Face, frames: int, rig=None) -> dict:
    """All measurements for one face (see module docstring)."""
    with tempfile.TemporaryDirectory() as cache:
        os.environ["FACEPUPPET_CACHE"] = cache
        sibson_s = median_time(lambda: Runtime(face, rig, cache=False), 1)
        Runtime(face, rig)
        load_s = median_time(lambda: Runtime(face, rig), 3)
        runtime = Runtime(face, rig)
    k = len(runtime.control_points)
    rng = np.random.default_rng(7)
    scale = 0.01 * float(np.ptp(face.vertices[:, 1]))
    displacements = rng.normal(scale=scale, size=(frames, k, 3))
    jaw = runtime.rig.rigid_parts["jaw"]
    motions = [{"jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, a))}
               for a in np.radians(rng.uniform(0, 15, frames))]
    out = np.empty_like(runtime.rest)
    normals = np.empty_like(runtime.rest)
    frame = iter(range(10**9))

    def deform() -> None:
        i = next(frame) % frames
        runtime.deform(displacements[i], motions[i], out=out)

    def deform_normals() -> None:
        i = next(frame) % frames
        runtime.deform_with_normals(displacements[i], motions[i], out=out, normals_out=normals)

    dense = _dense_baseline(runtime)
    weights = rng.uniform(0, 1, size=(frames, k)).astype(np.float32)

    def blend() -> None:
        i = next(frame) % frames
        np.add(dense[1], (dense[0] @ weights[i]).reshape(-1, 3), out=dense[2])

    deform_ms = 1e3 * median_time(deform, frames)
    dense_ms = 1e3 * median_time(blend, frames)
    return {
        "face": face.name,
        "vertices": len(face.vertices),
        "triangles": len(face.triangles),
        "control_points": k,
        "sibson_s": sibson_s,
        "load_s": load_s,
        "deform_ms": deform_ms,
        "deform_normals_ms": 1e3 * median_time(deform_normals, frames),
        "dense_ms": dense_ms,
        "ratio": dense_ms / deform_ms,
    }


def _dense_baseline(runtime: Runtime) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(deltas (3V x K) float32, rest (V, 3), output buffer): one dense delta per control point."""
    deltas = np.ascontiguousarray(np.repeat(runtime.B.toarray(), 3, axis=0), dtype=np.float32)
    rest = runtime.rest.astype(np.float32)
    return deltas, rest, np.empty_like(rest)


def bench_faces(ict: bool) -> list[tuple[Face, object]]:
    """The meshes to measure: default, subdivided twice over, and ICT when present."""
    face = load_face()
    faces: list[tuple[Face, object]] = [(face, None), (subdivide(face, 1), None), (subdivide(face, 2), None)]
    if ict:
        from .ict import ict_face_and_rig

        found = ict_face_and_rig()
        if found is not None:
            faces.append(found)
    return faces


def run_bench(frames: int = 300, as_json: bool = False, ict: bool = True) -> int:
    """Measure every mesh and print a table (or JSON); return the process exit code."""
    rows = [bench_face(face, frames, rig) for face, rig in bench_faces(ict)]
    if as_json:
        print(json.dumps(rows, indent=1))
        return 0
    header = ("face", "vertices", "control_points", "sibson_s", "load_s", "deform_ms",
              "deform_normals_ms", "dense_ms", "ratio")
    print("  ".join(f"{h:>17}" for h in header))
    for row in rows:
        print("  ".join(f"{row[h]:>17.4g}" if isinstance(row[h], float) else f"{row[h]!s:>17}" for h in header))
    return 0


def shared_assets() -> Path:
    """``../shared/assets`` beside the repository (``$FACEPUPPET_SHARED`` overrides ../shared)."""
    root = os.environ.get("FACEPUPPET_SHARED")
    if root:
        return Path(root) / "assets"
    return Path(__file__).resolve().parents[2] / "shared" / "assets"
