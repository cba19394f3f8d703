"""Time one frame of the default face through its high-level poses: the six expressions and the
15 visemes, each ramped from nothing to full strength (``Runtime.deform_faps``, positions), as a
performance moves through them. The fold guard's cost is in it: the rig's ``guarded`` triangles
are checked every frame and pushed back where a pose folds them.

    PYTHONPATH=. python tools/bench/bench_expressions.py [--rounds N]

Prints the median and 90th percentile milliseconds per frame. To compare two checkouts, run this
file with each one's code, in turns, in the same run (``cd OTHER && PYTHONPATH=. python
THIS/tools/bench/bench_expressions.py``): 0.237 ms median on 260bb82 and 0.238-0.245 ms after the
teeth and the faster fold search, here, three rounds each.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import puppet

STEPS = 16  # frames per pose, from 1/16 of its strength to all of it


def frames() -> list[dict]:
    """The poses' frames, as ``deform_faps`` keywords: each expression (intensity 0-63) and
    viseme (blend 0-63) at ``STEPS`` strengths."""
    strengths = np.linspace(63 / STEPS, 63, STEPS).round().astype(int)
    out: list[dict] = [{"expression": (k, int(s), 0, 0)} for k in range(1, 7) for s in strengths]
    return out + [{"viseme": (k, 0, int(s))} for k in range(15) for s in strengths]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=5, help="passes through every pose (default 5)")
    args = parser.parse_args()
    runtime = puppet.Runtime(puppet.load_face())
    poses = frames()
    for pose in poses:  # warm up: caches, the guard's first fixes
        runtime.deform_faps(**pose)
    times = []
    for _ in range(args.rounds):
        for pose in poses:
            start = time.perf_counter()
            runtime.deform_faps(**pose)
            times.append(time.perf_counter() - start)
    ms = 1000 * np.array(times)
    print(f"{len(poses)} frames x {args.rounds}: median {np.median(ms):.3f} ms, 90th percentile "
          f"{np.percentile(ms, 90):.3f} ms")


if __name__ == "__main__":
    main()
