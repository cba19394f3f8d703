"""Speed-up of a Dask batch render over a serial loop, in one run: N short takes (cut from the
demo take) rendered one after another in this process, then on a LocalCluster of one
single-threaded worker process per core, in turns (the first round's workers start cold: they
import puppet and load the face). Prints wall times, the speed-ups, the machine's load, and
checks the videos are byte-identical.

It also prints how many cores the serial loop keeps busy (its CPU time, llvmpipe's threads and
the encoder's process included, over its wall time): the serial loop is already parallel, so on
C cores a batch can be at most C / that faster. On an idle machine that is the bound to compare
the speed-up with; on a busy one both are a share of what is left.

    python tools/bench/bench_batch.py [--takes 8] [--seconds 2.5] [--size 320x240] [--workers N]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from puppet.io.fapfile import read_fap, write_fap
from puppet.view import batch


def cut(stream, start: int, frames: int):
    """Frames start..start+frames of a take, as a take of its own."""
    window = slice(start, start + frames)
    return dataclasses.replace(
        stream, values=stream.values[window], mask=stream.mask[window], viseme=stream.viseme[window],
        expression=stream.expression[window], frame_numbers=stream.frame_numbers[window] - start,
        declared_frames=frames)


def load() -> str:
    return " ".join(open("/proc/loadavg").read().split()[:3])


def cpu_seconds() -> float:
    """CPU time of this process (all its threads) and its finished children (the encoders)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--takes", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=2.5)
    parser.add_argument("--size", default="320x240")
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--repeats", type=int, default=4, help="rounds of serial then dask; the first warms workers")
    args = parser.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))
    settings = batch.RenderSettings(size=size)
    demo = read_fap(ROOT / "puppet" / "data" / "demo_take.fap")
    frames = int(round(args.seconds * demo.fps))
    with tempfile.TemporaryDirectory() as root:
        takes = []
        for i in range(args.takes):
            start = (i * 5) % max(len(demo) - frames, 1)
            path = Path(root) / f"take{i}.fap"
            write_fap(path, cut(demo, start, frames))
            takes.append(str(path))
        (Path(root) / "serial").mkdir()
        print(f"{args.takes} takes of {frames} frames ({args.seconds} s) at {size[0]}x{size[1]}, "
              f"{os.cpu_count()} cores, load average before: {load()}")
        from dask.distributed import Client, LocalCluster

        start = time.perf_counter()
        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, env=batch.WORKER_ENV)
        print(f"cluster start: {time.perf_counter() - start:.2f} s")
        serial_s, dask_s, busy, same = [], [], [], True
        with cluster, Client(cluster):
            for round_ in range(args.repeats):
                start, cpu = time.perf_counter(), cpu_seconds()
                serial = batch.render_serial(takes, str(Path(root) / "serial"), settings)
                serial_s.append(time.perf_counter() - start)
                busy.append((cpu_seconds() - cpu) / serial_s[-1])
                start = time.perf_counter()
                results = batch.render_batch(takes, str(Path(root) / "dask"), settings,
                                             scheduler=cluster.scheduler_address)
                dask_s.append(time.perf_counter() - start)
                same &= all(a.ok and a.sha256 == b.sha256 for a, b in zip(serial, results))
                print(f"round {round_ + 1}{' (workers cold)' if round_ == 0 else ''}: serial {serial_s[-1]:.2f} s "
                      f"({busy[-1]:.2f} cores busy), dask {dask_s[-1]:.2f} s, speed-up {serial_s[-1] / dask_s[-1]:.2f}x  "
                      f"(load {load()})")
        warm = slice(1, None) if args.repeats > 1 else slice(None)
        ratio = statistics.median(serial_s[warm]) / statistics.median(dask_s[warm])
        cores = statistics.median(busy[warm])
        print(f"speed-up, median of warm rounds: {ratio:.2f}x; the serial loop kept {cores:.2f} cores busy, so "
              f"{args.workers} workers can be at most {args.workers / cores:.2f}x faster; "
              f"videos byte-identical to the serial loop's: {same}")

if __name__ == "__main__":
    main()
