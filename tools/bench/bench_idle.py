"""What idle life costs a live frame: ``Mapping.pose(t)`` with idle life on and off, taking turns
in one run (so a load that comes and goes on a shared machine hits both alike), the channels fed
random readings at 60 frames a second; prints the medians in microseconds and the difference.

With ``--session``, also whole ``LiveSession.frame()`` calls on the default face while its
device says nothing (the hands at rest): without idle life every frame deforms the face at rest,
with it a face that blinks, looks about and breathes (moving FAPs: the runtime's work for them).

    python tools/bench/bench_idle.py [--mapping mappings/arduino_sliders.yaml] [--frames 20000] [--session 200]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from devices.base import Sample
from puppet.live.mappingfile import load_mapping

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mapping", default=str(ROOT / "mappings" / "arduino_sliders.yaml"))
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--session", type=int, default=0, help="session frames to time as well (0: none)")
    args = parser.parse_args()
    pose_cost(args)
    if args.session:
        session_cost(args)


def pose_cost(args: argparse.Namespace) -> None:
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



def session_cost(args: argparse.Namespace) -> None:
    from devices import open_device
    from devices.simulated_serial import PtyJoystick
    from puppet.face.load import load_face
    from puppet.live.session import LiveSession
    from puppet.runtime.runtime import Runtime

    runtime = Runtime(load_face())
    times = {"on": [], "off": []}
    with PtyJoystick(rate=None) as silent:   # a port that opens and then says nothing
        box = open_device(f"serial://{silent.path}?protocol=ascii", "box")
        with LiveSession(ROOT / "mappings" / "arduino_sliders.yaml", face=runtime, devices={"box": box}) as s:
            life = s.mapping.idle
            for k in range(args.session):
                for name in ("on", "off") if k % 2 else ("off", "on"):
                    s.mapping.idle = life if name == "on" else None
                    t0 = time.perf_counter_ns()
                    s.frame()
                    times[name].append(time.perf_counter_ns() - t0)
    med = {name: statistics.median(v) / 1e6 for name, v in times.items()}
    print(f"{args.session} session frames, device silent: median {med['off']:.2f} ms without idle life, "
          f"{med['on']:.2f} ms with it (the runtime moving the lids, eyes and head)")


if __name__ == "__main__":
    main()
