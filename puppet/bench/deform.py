"""``puppet bench``: what the runtime costs, against a dense blendshape baseline, in one run.

For each mesh (the default face; it with its skin subdivided once and twice, about 23k and 75k
vertices; the ICT face when ``../shared/assets/ict_facekit`` is there) it measures, as medians
(``default-coarse`` is the default face on its coarse rig, ``build_rig(grid=False)``: the layout
before the skin grid and the calibrated FAP motions, the "before" of that change in the same run):

* ``rig_s``: auto-rigging the face from its feature points (``autorig.build_rig``: regions,
  control points, rigid parts, muscles), where it has them (the ICT face: from its 68 iBUG
  landmarks, converted when it is loaded);
* ``precompute_s``: building the runtime with no cache: every region's Sibson coordinates, the
  weighted coefficients, folding them into one matrix, the normals' set-up (the rig itself is
  built once beforehand, outside the timing);
* ``load_s``: building the same runtime from the on-disk coefficient cache;
* ``deform_ms`` and ``deform_normals_ms``: one frame of a smooth take (``performance``: every
  control point oscillating, the jaw opening and closing), positions only and positions + normals;
* ``realtime_ms``: the same frames (positions) in real-time mode, rebases included;
* ``dense_ms``: the same mesh and control points as dense blendshapes, one (V x 3) delta per
  control point (V x 3 x K, float32), one frame = rest + deltas @ weights; ``ratio`` is
  dense_ms / deform_ms. This is the baseline as specified, and it flatters the dense side: a
  DFFD input moves in 3D, so a blendshape rig doing the same needs 3K shapes (3x the work).

``puppet.bench.run`` runs the sections and prints the tables. A second table splits whole frames (``bench_frame_split``): FAP frame (the demo take, where the
face has feature points; the smooth take's displacements otherwise) -> control points -> DFFD ->
normals -> draw -> read-back of a 640x480 offscreen image, with the frames per second and the
share of the frame spent deforming (controls + DFFD + normals; no normals where the renderer's
draw sums them, as on a GPU: ``render.choose_normals``). A third table
(``puppet.bench.inputs``) pushes samples through each device adapter and its shipped mapping.

A muscle table (``bench_muscles``, default face): median ms of one frame (``Runtime.deform_faps``:
FAPs + muscles, positions) for the same contractions in each muscle mode -- ``control``
(control points + DFFD + fold guard), ``classic`` and ``improved`` (vertex modes) -- with the same
FAP frame without muscles as the baseline, in the same run. A held pose repeats one frame; a
moving one swings every muscle over its range (2 s a swing at 60 frames/s), so the fold guard
meets a new field every frame, as in a performance.

The DFFD path is single-threaded scipy; the baseline's BLAS may use threads, so for one-core
figures run it pinned: ``OPENBLAS_NUM_THREADS=1 taskset -c 1 puppet bench``.
"""

from __future__ import annotations

import contextlib
import os
import statistics
import tempfile
import time
from collections.abc import Callable, Iterator

import numpy as np

from puppet.bench.ict import ict_face_and_rig
from puppet.face import rigid
from puppet.face.autorig import build_rig, rig_for_face
from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.face.subdivide import subdivide
from puppet.runtime.runtime import MUSCLE_MODES, Runtime

MUSCLE_POSES = {  # name -> contractions (None: every muscle) at that value, or swinging over (low, high)
    "every muscle at 0.5": (None, 0.5),
    "every muscle 0.4-0.6, moving": (None, (0.4, 0.6)),
    "zygomatic major l+r at 3": (("zygomatic_major_l", "zygomatic_major_r"), 3.0),
}


def median_time(fn: Callable[[], object], repeat: int, warm_up: bool = True) -> float:
    """Median wall time of ``fn`` in seconds over ``repeat`` calls (after one warm-up call)."""
    if warm_up:
        fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


@contextlib.contextmanager
def _private_cache() -> Iterator[None]:
    """A fresh, empty coefficient cache for the duration (the user's cache is left alone)."""
    saved = os.environ.get("FACEPUPPET_CACHE")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["FACEPUPPET_CACHE"] = cache
        try:
            yield
        finally:
            if saved is None:
                del os.environ["FACEPUPPET_CACHE"]
            else:
                os.environ["FACEPUPPET_CACHE"] = saved


def bench_face(face: Face, frames: int, rig=None, label: str | None = None) -> dict:
    """All measurements for one face (see module docstring)."""
    rig = rig if rig is not None else rig_for_face(face)
    rig_s = median_time(lambda: build_rig(face), 3, warm_up=False) if face.feature_points else float("nan")
    with _private_cache():
        precompute_s = median_time(lambda: Runtime(face, rig, cache=False), 3, warm_up=False)
        Runtime(face, rig)
        load_s = median_time(lambda: Runtime(face, rig), 3)
        runtime = Runtime(face, rig)
        realtime = Runtime(face, rig, mode="realtime")
    rng = np.random.default_rng(7)
    displacements, motions = smooth_take(runtime, frames, rng)
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
    weights = rng.uniform(0, 1, size=(frames, runtime.B.shape[1])).astype(np.float32)

    def blend() -> None:
        i = next(frame) % frames
        np.add(dense[1], (dense[0] @ weights[i]).reshape(-1, 3), out=dense[2])

    def deform_realtime() -> None:
        i = next(frame) % frames
        realtime.deform(displacements[i], motions[i], out=out)

    deform_ms = 1e3 * median_time(deform, frames)
    dense_ms = 1e3 * median_time(blend, frames)
    return {
        "face": label or face.name,
        "vertices": len(face.vertices),
        "triangles": len(face.triangles),
        "control_points": len(runtime.control_points),
        "rig_s": rig_s,
        "precompute_s": precompute_s,
        "load_s": load_s,
        "deform_ms": deform_ms,
        "deform_normals_ms": 1e3 * median_time(deform_normals, frames),
        "realtime_ms": 1e3 * median_time(deform_realtime, frames),
        "dense_ms": dense_ms,
        "ratio": dense_ms / deform_ms,
    }


def performance(rng: np.random.Generator, frames: int, k: int, amplitude: float) -> tuple[np.ndarray, np.ndarray]:
    """A smooth take at 60 frames/s: every control point on its own slow oscillation (0.2-2 Hz)
    of up to ``amplitude``, and the jaw opening and closing up to 15 degrees."""
    t = np.arange(frames) / 60.0
    freq = rng.uniform(0.2, 2.0, size=(k, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(k, 3))
    size = rng.uniform(0, amplitude, size=(k, 3))
    displacements = size * np.sin(2 * np.pi * freq * t[:, None, None] + phase)
    angles = np.radians(7.5) * (1 - np.cos(2 * np.pi * 0.7 * t))
    return displacements, angles


def smooth_take(runtime: Runtime, frames: int, rng: np.random.Generator
                ) -> tuple[np.ndarray, list[dict[str, np.ndarray]]]:
    """``performance`` on a runtime's face, as the benches deform it: each frame's active point
    displacements (up to 3% of the face's height) and the jaw's rigid motion."""
    amplitude = 0.03 * float(np.ptp(runtime.face.vertices[:, 1]))
    displacements, angles = performance(rng, frames, len(runtime.control_points), amplitude)
    jaw = runtime.rig.rigid_parts["jaw"]
    return displacements, [{"jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, a))} for a in angles]


def bench_frame_split(face: Face, frames: int, rig=None, size: tuple[int, int] = (640, 480),
                      label: str | None = None) -> dict:
    """Median ms per step of a whole offscreen frame, and frames per second (module docstring)."""
    from puppet.view.renderer import Renderer

    runtime = Runtime(face, rig)
    inputs, kind = _frame_inputs(runtime, frames)
    steps = {"controls": [], "dffd": [], "normals": [], "draw": [], "read": []}
    out, normals = np.empty_like(runtime.rest), np.empty_like(runtime.rest)
    with Renderer.for_face(face, width=size[0], height=size[1]) as renderer:
        renderer.aim(face.vertices)
        for i in range(frames + 1):
            t = [time.perf_counter()]
            d, motions = inputs(i)
            t.append(time.perf_counter())
            runtime.deform(d, motions, out=out)
            t.append(time.perf_counter())
            if not renderer.gpu_normals:  # a draw that sums its own needs none (``choose_normals``)
                runtime.normals(out, motions, out=normals)
            t.append(time.perf_counter())
            renderer.draw(out, normals)
            renderer.finish()
            t.append(time.perf_counter())
            renderer.read()
            t.append(time.perf_counter())
            if i:  # the first frame warms up
                for step, a, b in zip(steps, t, t[1:]):
                    steps[step].append(b - a)
    ms = {f"{step}_ms": 1e3 * statistics.median(v) for step, v in steps.items()}
    frame = sum(ms.values())
    return {"face": label or face.name, "vertices": len(face.vertices), "input": kind, "size": f"{size[0]}x{size[1]}",
            **ms, "fps": 1e3 / frame,
            "deform_share": (ms["controls_ms"] + ms["dffd_ms"] + ms["normals_ms"]) / frame}


def bench_muscles(face: Face, frames: int, rig=None) -> list[dict]:
    """Per muscle pose, median ms per frame of the FAP-only baseline and each muscle mode (module
    docstring); the FAP frame opens the jaw and raises the lip corners a little."""
    runtime = Runtime(face, rig)
    fap = np.zeros(68)
    fap[[2, 11, 12]] = 200.0, 60.0, 60.0
    out = np.empty_like(runtime.rest)
    repeat = max(1, min(frames, 60))
    rows = []
    for pose_name, (names, value) in MUSCLE_POSES.items():
        poses = _muscle_frames(runtime.muscle_names if names is None else names, value)
        row = {"face": face.name, "pose": pose_name,
               "fap_only_ms": 1e3 * median_time(lambda: runtime.deform_faps(fap, out=out), repeat)}
        for mode in MUSCLE_MODES:
            frame = iter(range(10**9))
            row[f"{mode}_ms"] = 1e3 * median_time(
                lambda mode=mode, frame=frame: runtime.deform_faps(fap, muscles=poses[next(frame) % len(poses)], mode=mode, out=out),
                repeat)
        rows.append(row)
    return rows


def _muscle_frames(names, value) -> list[dict[str, float]]:
    """The contractions of each frame: one held value, or a swing over (low, high) in 120 frames."""
    if not isinstance(value, tuple):
        return [dict.fromkeys(names, value)]
    low, high = value
    swing = low + (high - low) * 0.5 * (1 - np.cos(2 * np.pi * np.arange(120) / 120))
    return [dict.fromkeys(names, float(c)) for c in swing]


def _frame_inputs(runtime: Runtime, frames: int):
    """Per frame index, the runtime's inputs: from the demo take's FAPs, or the smooth take."""
    if "2.1" in runtime.face.feature_points:
        from puppet.fap.held import held_low_level
        from puppet.io.fapfile import iter_fap
        from puppet.view.demo import demo_take

        with iter_fap(demo_take()) as reader:
            take = list(held_low_level(reader))
        return (lambda i: runtime.faps.controls(take[i % len(take)])), "FAP"
    d, motions = smooth_take(runtime, frames + 1, np.random.default_rng(7))
    return (lambda i: (d[i], motions[i])), "displacements"


def _dense_baseline(runtime: Runtime) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(deltas (3V x K) float32, rest (V, 3), output buffer): one dense delta per control point."""
    deltas = np.ascontiguousarray(np.repeat(runtime.B.toarray(), 3, axis=0), dtype=np.float32)
    rest = runtime.rest.astype(np.float32)
    return deltas, rest, np.empty_like(rest)


def bench_faces(ict: bool, subdivided: bool = True) -> list[tuple[Face, object, str]]:
    """The meshes to measure, with their rig and label: default (and on its coarse rig),
    subdivided twice over, and ICT when present."""
    face = load_face()
    coarse = build_rig(face, grid=False, calibrated=False)
    faces = [(face, None, "default"), (face, coarse, "default-coarse")]
    if subdivided:
        faces += [(f, None, f.name) for f in (subdivide(face, 1), subdivide(face, 2))]
    if ict:
        found = ict_face_and_rig()
        if found is not None:
            faces.append((*found, found[0].name))
    return faces
