"""A face's ARKit route: per ARKit blendshape, the FAP vector that best reproduces the artist's
shape of it on that face as calibrated, and the two mappings that send a tracker's blendshapes
there (``arkit_csv.yaml`` for Live Link Face CSV takes, ``arkit_osc.yaml`` for a phone tracker
over OSC / VMC).

The vectors are the fold-safe calibration's fits (``puppet.runtime.foldlimits.fold_safe_calibration``:
``fit_faps`` of each example on the calibrated rig within its fold limits), rounded to whole FAPU,
with the relative RMS residual each leaves (``arkit_document``). A weight w of a blendshape adds
w x the vector: a row ``{fap: F, source: S, range: [0, v]}`` per FAP of the vector, FAPs under
``SMALLEST`` FAPU left out; every blendshape's rows carry a comment with how much of the artist's
shape the vector leaves unexplained (``write_routes``). Head and eye angles (the CSV's) keep
their hand-written rows: they are angles, not shapes.

Two callers, one code: ``tools/builders/build_default_rig.py`` and ``tools/builders/build_arkit_mappings.py`` solve
and write the shipped route of the default face (``puppet/data/arkit_faps.json``,
``mappings/arkit_*.yaml``); ``puppet calibrate-face`` with ARKit-named examples (a perfect-sync
GLB's morph targets) writes the face's own into its folder (``write_face_route``). A face's route
covers the blendshapes it has examples of; the others keep the default face's vectors, marked so.
"""

from __future__ import annotations

import importlib.resources
import json
import os
import re
from pathlib import Path

import numpy as np

from puppet.face.examples import ARKIT_NAMES
from puppet.fap.table import fap
from puppet.runtime.fapcalibration import Calibration, relative_residual
from puppet.runtime.runtime import Runtime

SHIPPED_VECTORS = "arkit_faps.json"
"""The default face's vectors, in the package's data folder (``puppet/data``)."""
ROUTES = ("arkit_csv.yaml", "arkit_osc.yaml")
SMALLEST = 5.0
DESCRIPTION = ("ARKit blendshape -> the FAP vector (FAPU) that best reproduces the artist's shape on {face} "
               "within its fold limits (puppet.runtime.fapcalibration.fit_faps), and the relative RMS residual it "
               "leaves over the vertices the shape moves")
DEFAULT_FACE = "the calibrated default face"

ONE_EURO = "{type: one_euro, min_cutoff: %s, beta: %s, d_cutoff: 1.0}"
CHANNEL_OPTIONS = {  # how each route shapes a channel before the targets; the rest: a small dead zone
    "csv": {"eyeBlinkLeft": "{max: 0.85}          # ARKit rarely reports a full blink: 0.85 closes",
            "eyeBlinkRight": "{max: 0.85}", "jawOpen": "{}", "mouthSmileLeft": "{}", "mouthSmileRight": "{}",
            "browInnerUp": "{}"},
    "phone": {"jawOpen": "{smoothing: %s}" % (ONE_EURO % ("2.0", "2.0")),
              "mouthSmileLeft": "{smoothing: %s}" % (ONE_EURO % ("2.0", "1.0")),
              "mouthSmileRight": "{smoothing: %s}" % (ONE_EURO % ("2.0", "1.0")),
              "eyeBlinkLeft": "{max: 0.85, smoothing: %s}   # trackers rarely report a full blink"
                              % (ONE_EURO % ("4.0", "5.0")),
              "eyeBlinkRight": "{max: 0.85, smoothing: %s}" % (ONE_EURO % ("4.0", "5.0")),
              "browInnerUp": "{smoothing: %s}" % (ONE_EURO % ("1.5", "1.0"))},
}

CSV_HEADER = """\
# yaml-language-server: $schema=schema.json
#
# Written by tools/builders/build_arkit_mappings.py: edit that, not this file.
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
# Written by tools/builders/build_arkit_mappings.py: edit that, not this file.
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
    """One channel per blendshape, shaped as ``CHANNEL_OPTIONS`` says (else a small dead zone)."""
    options = CHANNEL_OPTIONS[device]
    return [f"  {device}.{rename(s)}: {options.get(s, '{dead_zone: 0.05}')}" for s in shapes]


def target_lines(device: str, vectors: dict, residuals: dict, rename) -> list[str]:
    """Each blendshape's rows under a comment with its residual (none: the default face's vector)."""
    lines = []
    for shape, vector in vectors.items():
        rows = [(fap, value) for fap, value in vector.items() if abs(value) >= SMALLEST]
        if shape in residuals:
            lines.append(f"  # {shape}: leaves {residuals[shape]:.2f} of the example unexplained"
                         + ("" if rows else "; no FAP of this face reproduces it"))
        else:
            lines.append(f"  # {shape}: no example of this face; the default face's vector")
        lines += [f"  - {{fap: {fap}, source: {device}.{rename(shape)}, range: [0, {value:g}]}}" for fap, value in rows]
    return lines


def _write(path: Path, header: str, channels: list[str], targets: list[str]) -> None:
    text = header + "\nchannels:\n" + "\n".join(channels) + "\n\ntargets:\n" + "\n".join(targets) + "\n"
    path.write_text(text)


def write_routes(document: dict, folder: str | os.PathLike, *, face: str | None = None) -> list[Path]:
    """``arkit_csv.yaml`` and ``arkit_osc.yaml`` in ``folder`` from ``document``'s vectors and
    residuals (``arkit_document``): the shipped ones for ``face`` None, else the route of the face
    so described (its headers say so, and point at the ``arkit_faps.json`` beside them)."""
    folder = Path(folder)
    vectors, residuals = document["faps"], document["residual"]
    shapes = sorted(vectors)
    csv_header, osc_header = (CSV_HEADER, OSC_HEADER) if face is None else (_for_face(CSV_HEADER, face),
                                                                           _for_face(OSC_HEADER, face))
    paths = [folder / name for name in ROUTES]
    _write(paths[0], csv_header, channel_lines("csv", shapes, csv_name) + CSV_ANGLES.rstrip("\n").split("\n"),
           target_lines("csv", vectors, residuals, csv_name) + [""] + CSV_ANGLE_TARGETS.rstrip("\n").split("\n"))
    _write(paths[1], osc_header, channel_lines("phone", shapes, vmc_name),
           target_lines("phone", vectors, residuals, vmc_name))
    return paths


def _for_face(header: str, face: str) -> str:
    """A shipped route's header made the header of ``face``'s own route."""
    return (header.replace("# yaml-language-server: $schema=schema.json\n#\n", "")
            .replace("# Written by tools/builders/build_arkit_mappings.py: edit that, not this file.",
                     f"# Written by puppet calibrate-face for {face}: calibrate again rather than edit.\n"
                     "# Blendshapes the face has no example of keep the default face's vectors.")
            .replace(f"on {DEFAULT_FACE} (puppet/data/arkit_faps.json,",
                     "on this face (arkit_faps.json beside this file,"))


def arkit_document(face, calibration: Calibration, examples, *, face_label: str = DEFAULT_FACE,
                   source: str | None = None) -> dict:
    """The ARKit vectors of a fold-safe calibration (its ``weights``, the fits within its limits) of
    the ARKit-named ``examples``: {description, source, faps: {shape: {FAP name: FAPU}}, residual:
    {shape: relative residual on the calibrated rig}}, as ``puppet/data/arkit_faps.json`` holds."""
    runtime = Runtime(face, calibration.rig, dtype=np.float64)
    weights = {name: values for name, values in sorted(calibration.weights.items()) if name in ARKIT_NAMES}
    vectors = {name: {fap(i + 1).name: round(float(v)) for i, v in enumerate(values) if round(float(v))}
               for name, values in weights.items()}
    residuals = {name: round(relative_residual(runtime, values, examples[name]), 3) for name, values in weights.items()}
    document = {"description": DESCRIPTION.format(face=face_label)}
    if source is not None:
        document["source"] = source
    return document | {"faps": vectors, "residual": residuals}


def shipped_vectors() -> dict:
    """The default face's ARKit document (``puppet/data/arkit_faps.json``)."""
    return json.loads(importlib.resources.files("puppet").joinpath("data", SHIPPED_VECTORS).read_text("utf-8"))


def write_face_route(document: dict, folder: str | os.PathLike, face: str) -> list[Path]:
    """The face's ``arkit_faps.json`` (its own vectors) and its two routes in ``folder``: its own
    vectors where it has them, the default face's for the other blendshapes."""
    folder = Path(folder)
    (folder / SHIPPED_VECTORS).write_text(json.dumps(document, indent=1) + "\n")
    merged = {"faps": shipped_vectors()["faps"] | document["faps"], "residual": document["residual"]}
    return [folder / SHIPPED_VECTORS, *write_routes(merged, folder, face=face)]


def remove_face_route(folder: str | os.PathLike) -> list[Path]:
    """Remove a face route (``write_face_route``) from ``folder`` and return what was there: after
    a calibration from shapes with no ARKit names, an earlier route's vectors were fitted to the
    rig this one replaces, and would drive it wrong."""
    there = [path for path in (Path(folder) / name for name in (SHIPPED_VECTORS, *ROUTES)) if path.is_file()]
    for path in there:
        path.unlink()
    return there
