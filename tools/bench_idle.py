"""What idle life costs a live frame: ``Mapping.pose(t)`` with idle life on and off, taking turns
in one run (so a load that comes and goes on a shared machine hits both alike), the channels fed
as the slider box feeds them; prints the medians in microseconds and the difference.

    python tools/bench_idle.py [--mapping mappings/arduino_sliders.yaml] [--frames 20000]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from devices.base import Sample
from puppet.live.mappingfile import load_mapping

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mapping", default=str(ROOT / "mappings" / "arduino_sliders.yaml"))
    parser.add_argument("--frames", type=int, default=20000)
    args = parser.parse_args()
    on, off = load_mapping(args.mapping), load_mapping(args.mapping)
    off.idle = None
    rng = np.random.default_rng(0)
    device = next(iter(on.devices))
    names = [c.split(".", 1)[1] for c in on.channel_names if c.startswith(f"{device}.")]
    start = time.monotonic_ns()
    times = {"on": [], "off": []}
    for k in range(args.frames):
        t = start + k * 16_666_667                                   # 60 frames a second
        values = {name: float(v) for name, v in zip(names, rng.uniform(0, 1023, len(names)))}
        if k % 4:                                                    # a quarter of frames: no sample
            for m in (on, off):
                m.feed(Sample(t, device, values))
        for name, m in (("on", on), ("off", off)) if k % 2 else (("off", off), ("on", on)):
            t0 = time.perf_counter_ns()
            m.pose(t)
            times[name].append(time.perf_counter_ns() - t0)
    med = {name: statistics.median(v) / 1000 for name, v in times.items()}
    print(f"{args.frames} frames of {Path(args.mapping).name}: pose median {med['off']:.1f} us without idle life, "
          f"{med['on']:.1f} us with it: +{med['on'] - med['off']:.1f} us a frame")


if __name__ == "__main__":
    main()
