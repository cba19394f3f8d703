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

A second table splits whole frames (``bench_frame_split``): FAP frame (the demo take, where the
face has feature points; the smooth take's displacements otherwise) -> control points -> DFFD ->
normals -> draw -> read-back of a 640x480 offscreen image, with the frames per second and the
share of the frame spent deforming (controls + DFFD + normals). A third table
(``puppet.inputbench``) pushes samples through each device adapter and its shipped mapping.

A muscle table (``bench_muscles``, default face): median ms of one frame (``Runtime.pose``:
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
import functools
import json
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from . import rigid
from .autorig import build_rig, rig_for_face
from .face import Face, load_face
from .inputbench import bench_inputs
from .runtime import MUSCLE_MODES, Runtime
from .subdivide import subdivide

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
    k = len(runtime.control_points)
    rng = np.random.default_rng(7)
    displacements, angles = performance(rng, frames, k, 0.03 * float(np.ptp(face.vertices[:, 1])))
    jaw = runtime.rig.rigid_parts["jaw"]
    motions = [{"jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, a))} for a in angles]
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
        "control_points": k,
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


def bench_frame_split(face: Face, frames: int, rig=None, size: tuple[int, int] = (640, 480),
                      label: str | None = None) -> dict:
    """Median ms per step of a whole offscreen frame, and frames per second (module docstring)."""
    from .render import Renderer

    runtime = Runtime(face, rig)
    inputs, kind = _frame_inputs(runtime, frames)
    steps = {"controls": [], "dffd": [], "normals": [], "draw": [], "read": []}
    out, normals = np.empty_like(runtime.rest), np.empty_like(runtime.rest)
    with Renderer.for_face(face, width=size[0], height=size[1]) as renderer:
        renderer.frame(face.vertices)
        for i in range(frames + 1):
            t = [time.perf_counter()]
            d, motions = inputs(i)
            t.append(time.perf_counter())
            runtime.deform(d, motions, out=out)
            t.append(time.perf_counter())
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
               "fap_only_ms": 1e3 * median_time(lambda: runtime.pose(fap, out=out), repeat)}
        for mode in MUSCLE_MODES:
            frame = iter(range(10**9))
            row[f"{mode}_ms"] = 1e3 * median_time(
                lambda mode=mode, frame=frame: runtime.pose(fap, muscles=poses[next(frame) % len(poses)], mode=mode, out=out),
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
        from .demo import demo_take
        from .fapfile import iter_fap
        from .playback import held_low_level

        with iter_fap(demo_take()) as reader:
            take = list(held_low_level(reader, runtime))
        return (lambda i: runtime.faps.controls(take[i % len(take)])), "FAP"
    rng = np.random.default_rng(7)
    d, angles = performance(rng, frames + 1, len(runtime.control_points), 0.03 * float(np.ptp(runtime.rest[:, 1])))
    jaw = runtime.rig.rigid_parts["jaw"]
    return (lambda i: (d[i], {"jaw": rigid.about(jaw.pivot, rigid.rotation(jaw.axis, angles[i]))})), "displacements"


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
        from .ict import ict_face_and_rig

        found = ict_face_and_rig()
        if found is not None:
            faces.append((*found, found[0].name))
    return faces


SECTIONS = ("deform", "frames", "muscles", "inputs", "latency", "flood", "long_take")
"""What ``puppet bench --only`` can pick, in the order they run and print."""


def run_bench(frames: int = 300, as_json: bool = False, ict: bool = True, flood_seconds: float = 60.0,
              take_seconds: float = 3600.0, only: tuple[str, ...] = SECTIONS, quick: bool = False) -> int:
    """Measure the ``only`` sections (every mesh, the inputs, the live pipeline); print tables (or
    JSON) and report progress on stderr; return the process exit code. ``quick``: a minute's
    worth (30 frames, no subdivided meshes, a 3 s flood, a 1 minute take)."""
    unknown = sorted(set(only) - set(SECTIONS))
    if unknown:
        raise ValueError(f"unknown bench sections {unknown}: expected some of {', '.join(SECTIONS)}")
    if quick:
        frames, flood_seconds, take_seconds = min(frames, 30), min(flood_seconds, 3.0), min(take_seconds, 60.0)
    steps = _steps(frames, ict, flood_seconds, take_seconds, only, quick)
    report: dict[str, object] = {}
    with Steps(len(steps)) as progress:
        for section, label, measure in steps:
            progress.start(f"{section}: {label}")
            result = measure()
            if isinstance(result, list) and section in ("deform", "frames"):
                report.setdefault(section, []).extend(result)
            else:
                report[section] = result
    if as_json:
        print(json.dumps(report, indent=1))
    else:
        _print_report(report)
    return 0


def _steps(frames: int, ict: bool, flood_seconds: float, take_seconds: float, only: tuple[str, ...],
           quick: bool) -> list[tuple[str, str, Callable[[], object]]]:
    """(section, label, measurement) for each step of the run, faces made on first use."""
    faces = functools.cache(lambda: bench_faces(ict and not quick, subdivided=not quick))
    default = functools.cache(lambda: Runtime(faces()[0][0]))
    steps: list[tuple[str, str, Callable[[], object]]] = []
    if "deform" in only:
        labels = ["default", "default-coarse"] + ([] if quick else ["default-sub1", "default-sub2"] + ["ict"] * ict)
        for k, label in enumerate(labels):
            steps.append(("deform", label, lambda k=k: [bench_face(f, frames, rig, name)
                                                        for f, rig, name in faces()[k:k + 1]]))
    if "frames" in only:
        steps.append(("frames", "default", lambda: [bench_frame_split(faces()[0][0], min(frames, 120), label="default")]))
        if ict and not quick:
            steps.append(("frames", "ict", lambda: [bench_frame_split(face, min(frames, 120), rig, label=label)
                                                    for face, rig, label in faces() if face.name == "ict"]))
    if "muscles" in only:
        steps.append(("muscles", "default", lambda: bench_muscles(faces()[0][0], frames)))
    if "inputs" in only:
        steps.append(("inputs", "every adapter", lambda: bench_inputs(0.5 if quick else 2.0)))
    live = _live_sections(default, flood_seconds, take_seconds)
    steps += [(name, label, fn) for name, (label, fn) in live.items() if name in only]
    return steps


def _live_sections(runtime: Callable[[], Runtime], flood_seconds: float,
                   take_seconds: float) -> dict[str, tuple[str, Callable[[], dict]]]:
    """The live pipeline on the default face: latency, a flood of input, a long take."""
    from . import loadbench

    return {"latency": ("sim slider box -> drawn frame", lambda: loadbench.latency(runtime())),
            "flood": (f"{flood_seconds:g} s of 10,000 readings/s", lambda: loadbench.flood(runtime(), flood_seconds)),
            "long_take": (f"a {take_seconds:g} s take", lambda: loadbench.long_take(take_seconds))}


def _print_report(report: dict) -> None:
    if "deform" in report:
        _table(report["deform"], ("face", "vertices", "control_points", "rig_s", "precompute_s", "load_s",
                                  "deform_ms", "deform_normals_ms", "realtime_ms", "dense_ms", "ratio"))
        print()
    if "frames" in report:
        _table(report["frames"], ("face", "input", "size", "controls_ms", "dffd_ms", "normals_ms", "draw_ms",
                                  "read_ms", "fps", "deform_share"))
        print()
    if "muscles" in report:
        _table(report["muscles"], ("face", "pose", "fap_only_ms", *(f"{mode}_ms" for mode in MUSCLE_MODES)))
        print()
    if "inputs" in report:
        inputs = report["inputs"]
        _table([r for r in inputs if "error" not in r],
               ("adapter", "samples_s", "paced_samples_s", "latency_median_ms", "latency_p99_ms", "bad_frames"))
        for row in inputs:
            if "error" in row:
                print(f"{row['adapter']}: not measured ({row['error']})")
        print()
    _print_live(report)


def _print_live(report: dict) -> None:
    if "latency" in report:
        lat = report["latency"]
        work, mesh, drawn = lat["frame_work_ms"], lat["sample_to_mesh_ms"], lat["sample_to_drawn_ms"]
        print(f"live latency (a slider box in its own process -> default face, drawn and read back 640x480, "
              f"every sample to the first frame that shows it): frame work {work['median']:.2f} ms median / "
              f"{work['p99']:.2f} p99; draw and read-back {lat['draw_ms']['median']:.2f} ms median; sample->mesh {mesh['median']:.2f} / {mesh['p99']:.2f}; "
              f"sample->drawn {drawn['median']:.2f} ms median / {drawn['p99']:.2f} p99 at {lat['fps']:.0f} fps "
              f"({lat['samples']} samples)")
    if "flood" in report:
        flood = report["flood"]
        print(f"flood {flood['rate']:,.0f} readings/s for {flood['seconds']:g} s, recording: {flood['fps']:.1f} fps "
              f"(baseline {flood['baseline_fps']:.1f}, ratio {flood['fps_ratio']:.2f}), {flood['samples_s']:,.0f} "
              f"samples/s taken, memory {flood['rss_start_mb']:.1f} -> {flood['rss_end_mb']:.1f} MiB, "
              f"longest backlog {flood['backlog_max']}, dropped {flood['dropped']}")
    if "long_take" in report:
        take = report["long_take"]
        length = take["take_seconds"]
        print(f"long take {f'{length / 3600:g} h' if length >= 3600 else f'{length:g} s'} at an accelerated clock: {take['frames']:,} frames, "
              f"{take['samples']:,} samples in {take['wall_s']:.1f} s, memory growth {take['rss_growth_mb']:.2f} MiB, "
              f"take {take['take_mb']:.0f} MiB on disk")


class Steps:
    """Progress of a bench run on stderr: a rich progress bar on a terminal, else one line a step
    (stdout stays the report, so ``--json`` pipes cleanly)."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.done = 0
        self._bar = None
        if sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            self._bar = Progress(TextColumn("bench"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                                 TimeElapsedColumn(), TextColumn("{task.description}"),
                                 console=Console(stderr=True), transient=True)
            self._task = self._bar.add_task("", total=total)

    def __enter__(self) -> Steps:
        if self._bar is not None:
            self._bar.start()
        return self

    def start(self, label: str) -> None:
        """The next step begins (the previous one is done)."""
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done, description=label)
        else:
            print(f"bench {self.done + 1}/{self.total}: {label}", file=sys.stderr, flush=True)
        self.done += 1

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done)
            self._bar.stop()


def _table(rows: list[dict], header: tuple[str, ...]) -> None:
    widths = [max(len(h), 12, *(len(str(r[h])) for r in rows if isinstance(r[h], str))) for h in header]
    print("  ".join(f"{h:>{w}}" for h, w in zip(header, widths)))
    for row in rows:
        print("  ".join(f"{row[h]:>{w}.4g}" if isinstance(row[h], float) else f"{row[h]!s:>{w}}"
                        for h, w in zip(header, widths)))


def shared_assets() -> Path:
    """``../shared/assets`` beside the repository (``$FACEPUPPET_SHARED`` overrides ../shared)."""
    root = os.environ.get("FACEPUPPET_SHARED")
    if root:
        return Path(root) / "assets"
    return Path(__file__).resolve().parents[2] / "shared" / "assets"
