"""How well the default face's calibration carries over to faces of other shapes, where the truth is known.

    PYTHONPATH=. .venv/bin/python tools/transfer_check.py [--faces 3] [--spread 2.0] [--every 1] [--ict]

Faces of other shapes come from the shipped shape model (``puppet.photo.shapemodel``: MakeHuman's
own shape modifiers, a weight of 1 one standard deviation of its population): the default face
with weights drawn unit normal times ``--spread`` (seeds 1, 2, ...). Each is written as a bare
mesh (an OBJ of positions and triangles: no parts, contours or feature points) and loaded as a
user's mesh is, from landmarks: for now the default face's feature-point vertices (the same
topology, so they are the same places). Its rig is ``build_rig`` (without fold limits: their
search is another issue's), with the default face's FAP motions carried over, before and after:

* **before**: ``build_rig`` of the revision ``--before`` (default: where this branch left main),
  run from a copy of that revision's package (``git archive``) in a subprocess that saves the rig;
* **after**: ``build_rig`` here, as ``puppet rig`` now does it;

The truth: the artist's ARKit shapes (``../shared/assets/makehuman/faceunits_arkit``, deltas on
MakeHuman's base mesh) applied to the shaped face as the same deltas (turned into its face
frame). Figures per face and way: the median relative residual of the FAPs fitted to every
shape (``fapcalibration.fit_faps`` over the skin, ``relative_residual``: what ``tools/realism.py``
reports as "shipped rig, FAPs fit on skin" for the default face), beside the default face's own
on its shipped rig and on that rig without its fold limits (the shaped faces have none); the
folded triangles and creased edges (``puppet.runtime.posecheck``) summed over the six
expressions and 15 visemes, with the worst pose; and the seconds each took. ``--every K`` fits
every K-th shape only (quicker); ``--ict`` adds ICT-FaceKit's head (folds and creases only:
its truth is not known).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from puppet.bench.assets import shared_assets
from puppet.face.autorig import build_rig, rig_for_face
from puppet.face.default import default_face
from puppet.face.examples import load_examples
from puppet.face.load import load_face
from puppet.face.rig import Rig, load_rig
from puppet.photo.shapemodel import load_shape_model
from puppet.runtime.fapcalibration import fit_faps, relative_residual
from puppet.runtime.posecheck import pose_flaws
from puppet.runtime.runtime import Runtime

ROOT = Path(__file__).resolve().parents[1]
BEFORE_RIG = """
import json, sys
from puppet.face.autorig import build_rig
from puppet.face.load import load_face
from puppet.face.rig import save_rig
mesh, landmarks, out = sys.argv[1:4]
save_rig(build_rig(load_face(mesh, landmarks=json.loads(landmarks))), out)
"""
"""The subprocess that rigs a mesh with another revision's package."""


def write_bare_obj(path: Path, vertices: np.ndarray, triangles: np.ndarray) -> None:
    """An OBJ of positions and triangles only, as a user's exported mesh is."""
    lines = [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    path.write_text("\n".join(lines) + "\n")


def shaped_face(folder: Path, seed: int, spread: float) -> tuple[Path, dict[str, int]]:
    """The default face shaped by the shape model at weights ~ N(0, spread^2) (seeded), written as a
    bare OBJ, and its landmarks (the default face's feature-point vertices)."""
    face = default_face()
    model = load_shape_model()
    weights = np.random.default_rng(seed).normal(size=len(model)) * spread
    path = folder / f"shaped_{seed}.obj"
    write_bare_obj(path, np.asarray(face.vertices, float) + model.offsets(weights), np.asarray(face.triangles))
    return path, {k: int(v) for k, v in face.feature_vertices.items()}


def in_face_frame(face, shapes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The shapes' deltas turned as ``load_face`` turned the mesh into its face frame."""
    turn = np.eye(3) if face.placement is None else np.asarray(face.placement)[:, :3]
    return {name: D @ turn.T for name, D in shapes.items()}


def median_residual(runtime: Runtime, shapes: dict[str, np.ndarray]) -> float:
    """The median relative residual of the FAPs fitted to each shape (over the skin)."""
    return float(np.median([relative_residual(runtime, fit_faps(runtime, D), D) for D in shapes.values()]))


def flaws(runtime: Runtime, reference: Runtime) -> str:
    """Folds and creases summed over the expressions and visemes, and the worst pose."""
    found = pose_flaws(runtime, reference)
    worst = max(found, key=lambda k: (found[k].folds, found[k].creases))
    return (f"folds {sum(f.folds for f in found.values()):5d}  creases {sum(f.creases for f in found.values()):6d} "
            f"(of {next(iter(found.values())).edges} edges x {len(found)} poses; worst {worst}: "
            f"{found[worst].folds} folds, {found[worst].creases} creases)")


def transferred(face) -> Rig:
    """``face``'s rig with the default face's motions carried over, as ``puppet rig`` builds it."""
    return build_rig(face, calibrated=True)


class Before:
    """Rigs made by another revision's ``build_rig`` (its package copied out of git)."""

    def __init__(self, revision: str, folder: Path) -> None:
        self.package = folder / "before"
        self.package.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", revision, "puppet"], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(self.package)], input=archive, check=True)
        self.count = 0

    def rig(self, mesh: Path, landmarks) -> Rig:
        """The rig that revision builds for ``mesh`` with ``landmarks``."""
        self.count += 1
        out = self.package / f"rig_{self.count}.json"
        subprocess.run([sys.executable, "-c", BEFORE_RIG, str(mesh), json.dumps(landmarks), str(out)], check=True,
                       cwd=self.package, env=os.environ | {"PYTHONPATH": str(self.package)})
        return load_rig(out)


def measure_ways(face, mesh: Path, landmarks, before: Before, reference: Runtime,
                 shapes: dict[str, np.ndarray] | None) -> None:
    """Print each way's residual (when ``shapes`` are given), folds, creases and time."""
    for name in ("before", "after"):
        start = time.perf_counter()
        rig = before.rig(mesh, landmarks) if name == "before" else transferred(face)
        runtime = Runtime(face, rig, cache=False)
        rigged = time.perf_counter() - start
        residual = f"{median_residual(runtime, shapes):.3f}" if shapes else "  -  "
        print(f"  {name:<8} {residual}  {flaws(runtime, reference)}  "
              f"(rig {rigged:.1f} s, all {time.perf_counter() - start:.0f} s)")


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--faces", type=int, default=3, help="shaped faces (seeds 1..N)")
    parser.add_argument("--spread", type=float, default=2.0, help="shape weights' standard deviation")
    parser.add_argument("--every", type=int, default=1, help="fit every K-th ARKit shape only")
    parser.add_argument("--ict", action="store_true", help="add ICT-FaceKit's head (folds and creases)")
    parser.add_argument("--before", default=None,
                        help="the revision measured as before (default: merge-base with main)")
    return parser.parse_args()


def default_figures(default, shapes: dict[str, np.ndarray]) -> Runtime:
    """Print the default face's own residuals and flaws; its shipped runtime (the reference)."""
    shipped = rig_for_face(default)
    reference = Runtime(default, shipped, cache=False)
    unlimited = copy.copy(shipped)
    unlimited.fap_reach, unlimited.fap_follow = {}, {}
    start = time.perf_counter()
    print(f"default face, shipped rig:            {median_residual(reference, shapes):.3f}  "
          f"{flaws(reference, reference)}")
    free = median_residual(Runtime(default, unlimited, cache=False), shapes)
    print(f"default face, shipped rig, no limits: {free:.3f}  ({time.perf_counter() - start:.0f} s)")
    return reference


def main() -> None:
    args = arguments()
    revision = args.before or subprocess.run(["git", "-C", str(ROOT), "merge-base", "HEAD", "main"], check=True,
                                             capture_output=True, text=True).stdout.strip()
    default = default_face()
    examples = load_examples(default, shared_assets() / "makehuman" / "faceunits_arkit")
    shapes = dict(list({k: D for k, D in examples.items() if np.any(D)}.items())[::args.every])
    print(f"{len(shapes)} ARKit shapes; median residual of the FAPs fitted over the skin; before: {revision[:12]}")
    reference = default_figures(default, shapes)
    es = default.fapu["ES0"] * 1024
    with tempfile.TemporaryDirectory() as folder:
        before = Before(revision, Path(folder))
        for seed in range(1, args.faces + 1):
            mesh, landmarks = shaped_face(Path(folder), seed, args.spread)
            face = load_face(mesh, landmarks=landmarks)
            moved = np.linalg.norm(np.asarray(face.vertices) - np.asarray(default.vertices), axis=1)
            print(f"shaped face {seed}: skin moved {np.median(moved) / es:.3f} ES (median), "
                  f"up to {moved.max() / es:.3f}")
            measure_ways(face, mesh, landmarks, before, reference, in_face_frame(face, shapes))
        from tools.rig_faces import ict_inputs  # rig_faces draws a shaped face from here: imported late
        inputs = ict_inputs(shared_assets()) if args.ict else None
        if args.ict and inputs is None:
            print("ICT-FaceKit: not found, skipped")
        elif inputs is not None:
            print("ICT-FaceKit head (truth unknown: folds and creases only)")
            measure_ways(load_face(*inputs), *inputs, before, reference, None)


if __name__ == "__main__":
    main()
