"""Where the live loop's input-to-photon milliseconds go: the loop of ``puppet bench --only latency``
(the shipped slider box in a process of its own at 200 readings/s, the default face, a 640x480
offscreen frame with the live window's settings, drawn and read back), every stage of every frame
timed, wall clock and this thread's CPU:

* ``wait``: the loop waiting for a Sample (``LiveSession.wait_for_input``);
* ``frame``: ``LiveSession.frame``, split into ``controls`` (FAP engine), ``deform`` (DFFD,
  muscles and their fold guard, rigid parts; of it, the eye corners' ``sliver guard``, with the
  share of frames it had to fix) and ``normals``; what is left is draining the devices and the
  mapping;
* ``draw``: the renderer's GL calls (upload, llvmpipe's vertex work and binning run here);
* ``gl``: waiting for the GL to finish (``Renderer.finish``: llvmpipe's threads shade, the GIL is free);
* ``read``: reading the image back.

Then each Sample's latency (its timestamp to its frame read back) is split into the wait for
the frame being drawn when it came and its own frame. Medians and 99th percentiles; the process's
CPU time per frame, llvmpipe's threads included, shows how much of the two cores a frame takes.

``--leave-out teeth_upper,teeth_lower,tongue`` draws the face without those parts (the rest as
the live window draws it): what drawing them costs a frame and a Sample's latency.

    OPENBLAS_NUM_THREADS=1 python tools/bench/latency_profile.py [--seconds 20] [--size 640x480] [--leave-out PARTS]

The default, 20 s, is one whole cycle of the box's sliders (``pipeline.BOX_CYCLE_S``), as the bench's run.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from puppet.bench.pipeline import BOX_CYCLE_S, live_box
from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer
from puppet.view.rendertake import aim_at_head


class Stopwatch:
    """Wall and this thread's CPU nanoseconds per named stage, for the frame in progress."""

    def __init__(self) -> None:
        self.frame: dict[str, list[int]] = defaultdict(lambda: [0, 0])
        self.fixed = 0  # frames in which the sliver guard had to fix the eye corners

    def timed(self, name: str, fn):
        def wrapper(*args, **kwargs):
            wall, cpu = time.monotonic_ns(), time.thread_time_ns()
            try:
                return fn(*args, **kwargs)
            finally:
                entry = self.frame[name]
                entry[0] += time.monotonic_ns() - wall
                entry[1] += time.thread_time_ns() - cpu
        return wrapper

    def fixing(self, fn):
        """``fn`` (the sliver guard) counting the frames in which it had to fix."""
        def wrapper(*args, **kwargs):
            fixed = fn(*args, **kwargs)
            self.fixed += bool(fixed)
            return fixed
        return wrapper


def profile(seconds: float, size: tuple[int, int], leave_out: tuple[str, ...] = ()) -> None:
    runtime = Runtime(load_face())
    watch = Stopwatch()
    runtime.fap_controls = watch.timed("controls", runtime.fap_controls)
    runtime._deform = watch.timed("deform", runtime._deform)
    runtime._normals = watch.timed("normals", runtime._normals)
    runtime._slivers = watch.timed("sliver guard", watch.fixing(runtime._slivers))
    with live_box(runtime, size) as (session, renderer), contextlib.ExitStack() as stack:
        if leave_out:
            renderer = stack.enter_context(_drawn_without(runtime.face, leave_out, size))
        frames, latencies, process_cpu = _loop(session, renderer, watch, seconds)
    _report(frames, latencies, process_cpu)
    print(f"the sliver guard fixed the eye corners in {watch.fixed} of {len(frames)} frames "
          f"({100 * watch.fixed / max(len(frames), 1):.1f}%)")


def _drawn_without(face, parts: tuple[str, ...], size: tuple[int, int]) -> Renderer:
    """A renderer with the live window's settings that leaves ``parts`` of ``face`` out."""
    keep = np.ones(len(face.vertices), bool)
    for part in parts:
        if part not in face.parts:
            raise SystemExit(f"--leave-out: the face has no part {part!r} (it has {', '.join(face.parts)})")
        keep[face.parts[part]] = False
    triangles = np.asarray(face.triangles)
    drawn = triangles[keep[triangles].all(axis=1)]
    print(f"drawn without {', '.join(parts)}: {len(drawn)} of {len(triangles)} triangles")
    renderer = Renderer(drawn, len(face.vertices), face.colors, width=size[0], height=size[1])
    aim_at_head(renderer, face, "front")
    return renderer


def _loop(session, renderer, watch: Stopwatch, seconds: float):
    renderer.render(session.runtime.rest, session.runtime.rest_normals)  # warm-up
    session.frame()  # the Samples queued before the loop are not its latency (session.measure_latency)
    stages = {"wait": session.wait_for_input, "frame": session.frame, "draw": renderer.draw,
              "gl": renderer.finish, "read": renderer.read}
    stages = {name: watch.timed(name, fn) for name, fn in stages.items()}
    frames, latencies = [], []
    end = time.monotonic_ns() + int(seconds * 1e9)
    cpu_start, wall_start = time.process_time(), time.monotonic()
    while time.monotonic_ns() < end:
        watch.frame.clear()
        stages["wait"](0.1)
        start = time.monotonic_ns()
        f = stages["frame"]()
        stages["draw"](f.vertices, f.normals)
        stages["gl"]()
        stages["read"]()
        done = time.monotonic_ns()
        frames.append({name: tuple(v) for name, v in watch.frame.items()})
        latencies.extend((start - t, done - start) for t in f.sample_ns)
    process_cpu = (time.process_time() - cpu_start) / max(len(frames), 1), time.monotonic() - wall_start
    return frames, latencies, process_cpu


def _stats(values: list[float]) -> str:
    ordered = sorted(values)
    return f"{statistics.median(ordered):6.2f} {ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]:6.2f}"


def _report(frames: list[dict], latencies: list[tuple[int, int]], process_cpu) -> None:
    order = ["wait", "frame", "controls", "deform", "sliver guard", "normals", "draw", "gl", "read"]
    print(f"{len(frames)} frames in {process_cpu[1]:.1f} s ({len(frames) / process_cpu[1]:.0f} fps), "
          f"{len(latencies)} samples; load average {' '.join(open('/proc/loadavg').read().split()[:3])}")
    print(f"{'stage':12s} {'wall median p99':>16s}   {'cpu median p99':>15s}  (ms; controls, deform and normals "
          "are inside frame, the sliver guard inside deform)")
    for name in order:
        wall = [f[name][0] / 1e6 for f in frames if name in f]
        cpu = [f[name][1] / 1e6 for f in frames if name in f]
        if wall:
            print(f"{name:12s} {_stats(wall):>16s}   {_stats(cpu):>15s}")
    busy = [sum(f[n][0] for n in ("frame", "draw", "gl", "read") if n in f) / 1e6 for f in frames]
    print(f"{'frame total':12s} {_stats(busy):>16s}   process CPU per frame, all threads: {1e3 * process_cpu[0]:.2f} ms")
    waited = [w / 1e6 for w, _ in latencies]
    own = [o / 1e6 for _, o in latencies]
    total = [(w + o) / 1e6 for w, o in latencies]
    print(f"sample -> drawn {_stats(total)} = waiting for its frame to start {_stats(waited)} + its frame {_stats(own)} "
          "(median p99, ms)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=BOX_CYCLE_S)
    parser.add_argument("--size", default="640x480")
    parser.add_argument("--leave-out", default="", help="parts not drawn, comma-separated (e.g. teeth_upper)")
    args = parser.parse_args()
    leave_out = tuple(part for part in args.leave_out.split(",") if part)
    profile(args.seconds, tuple(int(x) for x in args.size.split("x")), leave_out)


if __name__ == "__main__":
    main()
