"""``puppet bench``: the sections of a run, their progress on stderr, and the report (tables or JSON).

The sections are the deform and whole-frame tables and the muscle modes (``puppet.bench.deform``),
the device adapters (``puppet.bench.inputs``) and the live pipeline: latency, a flood of input
and a long take (``puppet.bench.pipeline``), how long ``puppet rig`` takes, its fold-limit
search before and after in one run (``puppet.bench.rigtime``), and the show server's feed and
clients (``puppet.bench.show``).
"""

from __future__ import annotations

import functools
import json
import sys
from collections.abc import Callable

from puppet.bench import pipeline
from puppet.bench.deform import bench_face, bench_faces, bench_frame_split, bench_muscles
from puppet.bench.inputs import bench_inputs
from puppet.bench.rigtime import bench_rig
from puppet.bench.show import show
from puppet.bench.voice import voice
from puppet.runtime.runtime import MUSCLE_MODES, Runtime

SECTIONS = ("deform", "frames", "muscles", "inputs", "rig", "latency", "voice", "flood", "long_take", "show")
"""What ``puppet bench --only`` can pick, in the order they run and print."""


def run_bench(frames: int = 300, as_json: bool = False, ict: bool = True, flood_seconds: float = 60.0,
              take_seconds: float = 3600.0, only: tuple[str, ...] = SECTIONS, quick: bool = False,
              flood_rate: float = 10_000.0) -> int:
    """Measure the ``only`` sections (every mesh, the inputs, the live pipeline); print tables (or
    JSON) and report progress on stderr; return the process exit code. ``quick``: a minute's
    worth (30 frames, no subdivided meshes, a 3 s flood, a 1 minute take)."""
    unknown = sorted(set(only) - set(SECTIONS))
    if unknown:
        raise ValueError(f"unknown bench sections {unknown}: expected some of {', '.join(SECTIONS)}")
    if quick:
        frames, flood_seconds, take_seconds = min(frames, 30), min(flood_seconds, 3.0), min(take_seconds, 60.0)
    steps = _steps(frames, ict, flood_seconds, take_seconds, only, quick, flood_rate)
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
           quick: bool, flood_rate: float = 10_000.0) -> list[tuple[str, str, Callable[[], object]]]:
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
    if "rig" in only:
        rig_runs, rig_ict = (1, False) if quick else (3, ict)
        steps.append(("rig", "puppet rig, fold limits before and after", lambda: bench_rig(rig_runs, ict=rig_ict)))
    live = _live_sections(default, flood_seconds, take_seconds, 3.0 if quick else pipeline.BOX_CYCLE_S, flood_rate)
    steps += [(name, label, fn) for name, (label, fn) in live.items() if name in only]
    return steps


def _live_sections(runtime: Callable[[], Runtime], flood_seconds: float, take_seconds: float,
                   latency_seconds: float, flood_rate: float = 10_000.0) -> dict[str, tuple[str, Callable[[], dict]]]:
    """The live pipeline on the default face: latency, a flood of input, a long take."""
    return {"latency": ("sim slider box -> drawn frame", lambda: pipeline.latency(runtime(), latency_seconds)),
            "voice": ("wav:// bursts -> drawn frame", lambda: voice(runtime())),
            "flood": (f"{flood_seconds:g} s of {flood_rate:,.0f} readings/s",
                      lambda: pipeline.flood(runtime(), flood_seconds, flood_rate)),
            "long_take": (f"a {take_seconds:g} s take", lambda: pipeline.long_take(take_seconds)),
            "show": ("program feed in Chromium, live loop with 0 / 4 clients",
                     lambda: show(runtime(), min(latency_seconds, 10.0)))}


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
    if "rig" in report:
        _table(report["rig"], ("face", "vertices", "rig_s", "before_s", "after_s", "ratio", "total_s", "same"))
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
              f"({lat['samples']} samples; {lat['samples_before']} queued before the loop, not timed; "
              f"drawn by {lat['gl_renderer']}{_cores(lat['rasteriser_cores'])}, "
              f"normals on the {'GPU, in the draw' if lat['normals'] == 'draw' else 'CPU'})")
    if "voice" in report:
        sync = report["voice"]
        lag = sync["sound_to_drawn_ms"]
        print(f"voice (wav:// at real-time pace -> voice.yaml -> default face, drawn and read back 640x480): a sound's "
              f"onset to the first frame showing it {lag['median']:.1f} ms median / {lag['p99']:.1f} p99 over "
              f"{lag['bursts']} bursts; analysis {sync['analysis_ms_per_block']:.3f} ms CPU per 10 ms block; the "
              f"slider box's loop {sync['fps_without_mic']:.0f} fps without a microphone, {sync['fps_with_mic']:.0f} "
              f"with one (ratio {sync['fps_ratio']:.2f})")
    if "flood" in report:
        flood = report["flood"]
        print(f"flood {flood['rate']:,.0f} readings/s for {flood['seconds']:g} s, recording: {flood['fps']:.1f} fps "
              f"(baseline {flood['baseline_fps']:.1f}, ratio {flood['fps_ratio']:.2f}), {flood['samples_s']:,.0f} "
              f"samples/s taken, memory {flood['rss_start_mb']:.1f} -> {flood['rss_end_mb']:.1f} MiB "
              f"(peak {flood['rss_peak_mb']:.1f}), longest backlog {flood['backlog_max']}, dropped {flood['dropped']}; "
              f"raw log {flood['readings_logged']:,} of {flood['readings_sent']:,} readings sent "
              f"({flood['readings_missing']} missing)")
    if "show" in report:
        _print_show(report["show"])
    if "long_take" in report:
        take = report["long_take"]
        length = take["take_seconds"]
        print(f"long take {f'{length / 3600:g} h' if length >= 3600 else f'{length:g} s'} at an accelerated clock: {take['frames']:,} frames, "
              f"{take['samples']:,} samples in {take['wall_s']:.1f} s, memory growth {take['rss_growth_mb']:.2f} MiB, "
              f"take {take['take_mb']:.0f} MiB on disk")


def _print_show(show: dict) -> None:
    feed, crowd = show["feed"], show["clients"]
    if "error" in feed:
        print(f"program feed: not measured in a browser ({feed['error']})")
    else:
        delay = feed["delay_ms"]
        print(f"program feed ({feed['vertices']:,} vertices, {feed['size']}, the demo take at 30 fps into headless "
              f"Chromium): publish -> page drawn {delay['median']:.1f} ms median / {delay['p99']:.1f} p99 over "
              f"{feed['drawn']} frames drawn of {feed['frames']}; {feed['feed_kb_s']:.0f} kB/s and "
              f"{feed['encode_ms']:.2f} ms CPU a frame, against pictures with alpha: PNG {feed['png_kb_s']:.0f} kB/s "
              f"({feed['png_encode_ms']:.0f} ms a frame), WebP q80 {feed['webp_kb_s']:.0f} kB/s "
              f"({feed['webp_encode_ms']:.0f} ms)")
    runs = {k: crowd[k]["sample_to_drawn_ms"]["median"] for k in ("no_clients", "four_clients", "no_clients_again")}
    print(f"live loop with the show server (sample -> drawn, median, {crowd['seconds']:g} s each): no client "
          f"{runs['no_clients']:.1f} ms, four clients {runs['four_clients']:.1f} ms, none again "
          f"{runs['no_clients_again']:.1f} ms (ratio {crowd['ratio']:.2f}); the flooding client answered "
          f"{crowd['api_answers_s']:.0f} messages/s, {crowd['api_refused']} refused; the server's thread used "
          f"{crowd['server_cpu_share']:.1%} of a core meanwhile")


def _cores(cores: list[int]) -> str:
    """Where the latency's rasteriser threads ran: a core each (``rasterthreads.spread``), or
    wherever the scheduler put them (nothing to say)."""
    return f" on cores {', '.join(map(str, cores))}, a thread each" if cores else ""


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


