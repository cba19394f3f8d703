"""Write mappings/arkit_csv.yaml and mappings/arkit_osc.yaml: the ARKit routes, each blendshape
sent to the FAP vector that best reproduces it on the calibrated default face.

The vectors come from puppet/data/arkit_faps.json (tools/build_default_rig.py solves them with
puppet.runtime.fapcalibration.fit_faps against the artist-made example of each blendshape). A weight w of
a blendshape adds w x the vector: a row ``{fap: F, source: S, range: [0, v]}`` per FAP of the
vector, FAPs under ``SMALLEST`` FAPU left out. Every blendshape's rows carry a comment with how
much of the artist's shape the vector leaves unexplained. Head and eye angles (the CSV's) keep
their hand-written rows: they are angles, not shapes.

    python tools/build_arkit_mappings.py
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VECTORS = ROOT / "puppet" / "data" / "arkit_faps.json"
SMALLEST = 5.0

ONE_EURO = "{type: one_euro, min_cutoff: %s, beta: %s, d_cutoff: 1.0}"
CHANNEL_OPTIONS = {  # how each route shapes a channel before the targets; the rest: a small dead zone
    "csv": {"eyeBlinkLeft": "{max: 0.85}          # ARKit rarely reports a full blink: 0.85 closes",
            "eyeBlinkRight": "{max: 0.85}", "jawOpen": "{}", "mouthSmileLeft": "{}", "mouthSmileRight": "{}",
            "browInnerUp": "{}"},
    "phone": {"jawOpen": "{smoothing: %s}" % (ONE_EURO % ("2.0", "2.0")),
              "mouthSmileLeft": "{smoothing: %s}" % (ONE_EURO % ("2.0", "1.0")),
              "mouthSmileRight": "{smoothing: %s}" % (ONE_EURO % ("2.0", "1.0")),
              "eyeBlinkLeft": "{max: 0.85, smoothing: %s}   # trackers rarely report a full blink" % (ONE_EURO % ("4.0", "5.0")),
              "eyeBlinkRight": "{max: 0.85, smoothing: %s}" % (ONE_EURO % ("4.0", "5.0")),
              "browInnerUp": "{smoothing: %s}" % (ONE_EURO % ("1.5", "1.0"))},
}

CSV_HEADER = """\
# yaml-language-server: $schema=schema.json
#
# Written by tools/build_arkit_mappings.py: edit that, not this file.
#
# A Live Link Face (Epic's iPhone app) / ARKit blendshape CSV imported as a take by
# puppet.live.arkit.import_csv: every CSV row becomes one Sample from device `csv`, its channels named
# as in the CSV header (EyeBlinkLeft, JawOpen, MouthSmileLeft, ... -- not the _L / _R names of
# the VMC / OSC trackers, see arkit_osc.yaml). Blendshape weights are 0..1. Left / Right are the
# performer's own left and right, the face's own left and right in MPEG-4 (l / r in FAP names).
#
# Each blendshape drives the FAP vector that best reproduces the artist-made example of that
# blendshape on the calibrated default face (puppet/data/arkit_faps.json, solved by
# puppet.runtime.fapcalibration.fit_faps); its comment says how much of the example's motion the vector
# leaves unexplained (relative RMS residual). Targets that write the same FAP add up, so blends
# of blendshapes add as ARKit's do.
#
# Head and eye angles (HeadYaw, HeadPitch, HeadRoll, LeftEyeYaw, ...) are read as radians: the
# channels are bipolar over -1..1 (about +-57.3 degrees, far beyond any real head turn) and map
# linearly onto +-57.2958 degrees, so a value of 0.1 is 5.73 degrees whichever reading of the
# file is right (radians, or the app's "normalised" -1..1). Signs follow the MPEG-4 FAPs
# (yaw toward the face's left, pitch down, roll toward its right); flip a range to flip an axis.
#
# No smoothing: the take is a recording, already filtered by ARKit, and the importer samples it
# at the take's frame times; dead zones only keep resting noise off the face.
#
# The device is never opened by the importer (it feeds the rows itself); its URL replays nothing.
# To re-map an imported take live, point a replay device at the take's samples.jsonl.
description: Live Link Face / ARKit blendshape CSV (imported with puppet.live.arkit.import_csv)

devices:
  csv:
    url: "replay:///dev/null"
"""

CSV_ANGLES = """\
  csv.HeadYaw: {range: bipolar, min: -1, centre: 0, max: 1}
  csv.HeadPitch: {range: bipolar, min: -1, centre: 0, max: 1}
  csv.HeadRoll: {range: bipolar, min: -1, centre: 0, max: 1}
  csv.LeftEyeYaw: {range: bipolar, min: -1, centre: 0, max: 1}
  csv.LeftEyePitch: {range: bipolar, min: -1, centre: 0, max: 1}
  csv.RightEyeYaw: {range: bipolar, min: -1, centre: 0, max: 1}
  csv.RightEyePitch: {range: bipolar, min: -1, centre: 0, max: 1}
"""

CSV_ANGLE_TARGETS = """\
  # radians -> degrees (see the top of the file)
  - {head: yaw, source: csv.HeadYaw, range: [-57.2958, 57.2958]}
  - {head: pitch, source: csv.HeadPitch, range: [-57.2958, 57.2958]}
  - {head: roll, source: csv.HeadRoll, range: [-57.2958, 57.2958]}
  - {eye_l: yaw, source: csv.LeftEyeYaw, range: [-57.2958, 57.2958]}
  - {eye_l: pitch, source: csv.LeftEyePitch, range: [-57.2958, 57.2958]}
  - {eye_r: yaw, source: csv.RightEyeYaw, range: [-57.2958, 57.2958]}
  - {eye_r: pitch, source: csv.RightEyePitch, range: [-57.2958, 57.2958]}
"""

OSC_HEADER = """\
# yaml-language-server: $schema=schema.json
#
# Written by tools/build_arkit_mappings.py: edit that, not this file.
#
# A phone face tracker (ARKit blendshapes, e.g. through iFacialMocap or Waidayo) sending the VMC
# protocol over OSC: every /VMC/Ext/Blend/Apply arrives as one Sample of blendshape weights 0..1
# named as the tracker names them (JawOpen, MouthSmile_L, ...). _L / _R are the performer's own
# left and right, which are the face's own left and right in MPEG-4 (l / r in the FAP names).
#
# Each blendshape drives the FAP vector that best reproduces the artist-made example of that
# blendshape on the calibrated default face (puppet/data/arkit_faps.json, solved by
# puppet.runtime.fapcalibration.fit_faps); its comment says how much of the example's motion the vector
# leaves unexplained (relative RMS residual). Opposite shapes (BrowInnerUp and BrowDown_L,
# EyeBlink_L and EyeWide_L) write the same FAPs in opposite directions and add up. A light One
# Euro filter takes the tracker's jitter out of the jaw, smile, blink and brows.
description: ARKit blendshapes over OSC / VMC (phone face tracker)

devices:
  phone:
    url: "osc://127.0.0.1:39539"
"""


def csv_name(shape: str) -> str:
    """ARKit's ``mouthSmileLeft`` as Live Link Face's CSV header names it: ``MouthSmileLeft``."""
    return shape[0].upper() + shape[1:]


def vmc_name(shape: str) -> str:
    """ARKit's ``mouthSmileLeft`` as VMC trackers name it: ``MouthSmile_L``."""
    name = csv_name(shape)
    return re.sub(r"(Left|Right)$", lambda m: "_" + m.group(1)[0], name)


def channel_lines(device: str, shapes: list[str], rename) -> list[str]:
    options = CHANNEL_OPTIONS[device]
    return [f"  {device}.{rename(s)}: {options.get(s, '{dead_zone: 0.05}')}" for s in shapes]


def target_lines(device: str, vectors: dict, residuals: dict, rename) -> list[str]:
    lines = []
    for shape, vector in vectors.items():
        rows = [(fap, value) for fap, value in vector.items() if abs(value) >= SMALLEST]
        lines.append(f"  # {shape}: leaves {residuals[shape]:.2f} of the example unexplained"
                     + ("" if rows else "; no FAP of this face reproduces it"))
        lines += [f"  - {{fap: {fap}, source: {device}.{rename(shape)}, range: [0, {value:g}]}}" for fap, value in rows]
    return lines


def write(path: Path, header: str, channels: list[str], targets: list[str]) -> None:
    text = header + "\nchannels:\n" + "\n".join(channels) + "\n\ntargets:\n" + "\n".join(targets) + "\n"
    path.write_text(text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vectors", type=Path, default=VECTORS, help="the solved FAP vectors (JSON)")
    parser.add_argument("--out", type=Path, default=ROOT / "mappings", help="folder of the mappings")
    args = parser.parse_args(argv)
    document = json.loads(args.vectors.read_text())
    vectors, residuals = document["faps"], document["residual"]
    shapes = sorted(vectors)
    write(args.out / "arkit_csv.yaml", CSV_HEADER,
          channel_lines("csv", shapes, csv_name) + CSV_ANGLES.rstrip("\n").split("\n"),
          target_lines("csv", vectors, residuals, csv_name) + [""] + CSV_ANGLE_TARGETS.rstrip("\n").split("\n"))
    write(args.out / "arkit_osc.yaml", OSC_HEADER, channel_lines("phone", shapes, vmc_name),
          target_lines("phone", vectors, residuals, vmc_name))
    print(f"{args.out}: arkit_csv.yaml and arkit_osc.yaml, {len(shapes)} blendshapes each")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
