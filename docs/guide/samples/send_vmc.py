#!/usr/bin/env python3
"""Send a Live Link Face CSV to facepuppet the way a phone face tracker does: VMC over OSC.

    python send_vmc.py livelink_sample.csv [--host 127.0.0.1] [--port 39539] [--fps 60] [--loop]

Each CSV row becomes one VMC frame, a bundle of ``/VMC/Ext/Blend/Val <name> <value>`` messages
(one per blendshape) and ``/VMC/Ext/Blend/Apply``, sent over UDP at ``--fps`` frames a second.
Live Link Face's names (``EyeBlinkLeft``) become the VMC trackers' (``EyeBlink_L``), the names
the shipped ``arkit_osc`` mapping reads. Head and eye angles are left out: VMC trackers send
those as bones, which facepuppet does not read. Needs python-osc (the ``osc`` extra).
"""

from __future__ import annotations

import argparse
import csv
import time
from collections.abc import Iterator

from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import UDPClient

ANGLES = {"HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
          "RightEyeYaw", "RightEyePitch", "RightEyeRoll"}
NOT_SHAPES = {"Timecode", "BlendShapeCount"} | ANGLES


def vmc_name(name: str) -> str:
    """``EyeBlinkLeft`` -> ``EyeBlink_L``, ``JawRight`` -> ``Jaw_R``; others as they are."""
    for side, suffix in (("Left", "_L"), ("Right", "_R")):
        if name.endswith(side):
            return name[: -len(side)] + suffix
    return name


def frames(path: str) -> Iterator[dict[str, float]]:
    """The blendshape weights of each row of a Live Link Face CSV, under VMC names."""
    with open(path, newline="", encoding="utf-8-sig") as handle:
        for row in csv.DictReader(handle):
            yield {vmc_name(k): float(v) for k, v in row.items() if k not in NOT_SHAPES}


def vmc_frame(values: dict[str, float]) -> OscBundle:
    """One tracker frame as an OSC bundle: every blendshape's value, then Apply."""
    bundle = OscBundleBuilder(IMMEDIATELY)
    for name, value in values.items():
        message = OscMessageBuilder("/VMC/Ext/Blend/Val")
        message.add_arg(name)
        message.add_arg(value, "f")
        bundle.add_content(message.build())
    bundle.add_content(OscMessageBuilder("/VMC/Ext/Blend/Apply").build())
    return bundle.build()


def send(path: str, host: str = "127.0.0.1", port: int = 39539, fps: float = 60, loop: bool = False) -> int:
    """Send the CSV's rows as VMC frames (``fps`` 0: as fast as possible); returns frames sent."""
    client = UDPClient(host, port)
    sent = 0
    while True:
        start = time.monotonic()
        for k, values in enumerate(frames(path)):
            if fps > 0:
                time.sleep(max(0.0, start + k / fps - time.monotonic()))
            client.send(vmc_frame(values))
            sent += 1
        if not loop:
            return sent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("csv", help="a Live Link Face CSV")
    parser.add_argument("--host", default="127.0.0.1", help="where facepuppet listens (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=39539, help="its UDP port (default 39539)")
    parser.add_argument("--fps", type=float, default=60.0, help="frames a second (default 60; 0: flat out)")
    parser.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl+C")
    args = parser.parse_args()
    print(f"sent {send(args.csv, args.host, args.port, args.fps, args.loop)} frames to {args.host}:{args.port}")


if __name__ == "__main__":
    main()
