"""How well the default face's calibration carries over to faces of other shapes, where the truth is known.

    PYTHONPATH=. python tools/checks/transfer_check.py [--faces 3] [--spread 2.0] [--every 1] [--ict] [--found]

Faces of other shapes come from the shipped shape model (``puppet.photo.shapemodel``: MakeHuman's
own shape modifiers, a weight of 1 one standard deviation of its population): the default face
with weights drawn unit normal times ``--spread`` (seeds 1, 2, ...). Each is written as a bare
mesh (``write_bare_obj``: positions and triangles, no parts, contours or feature points) and
loaded as a user's mesh is, from landmarks: the default face's feature-point vertices (the same
topology, so they are the same places). Its rig is ``build_rig`` (without fold limits: their
search is another issue's), with the default face's FAP motions carried over, before and after:

* **before**: ``build_rig`` of the revision ``--before`` (default: where this branch left main),
  run from a copy of that revision's package (``git archive``) in a subprocess that saves the rig;
* **after**: ``build_rig`` here, as ``puppet rig`` now does it;

The truth: the artist's ARKit shapes (``../shared/assets/makehuman/faceunits_arkit``, deltas on
MakeHuman's base mesh) applied to the shaped face as the same deltas (turned into its face
frame). Figures per face and way: the median relative residual of the FAPs fitted to every
shape (``fapcalibration.fit_faps`` over the skin, ``relative_residual``: what ``tools/checks/realism.py``
reports as "shipped rig, FAPs fit on skin" for the default face), beside the default face's own
on its shipped rig and on that rig without its fold limits (the shaped faces have none); the
folded triangles and creased edges (``puppet.runtime.posecheck``) summed over the six
expressions and 15 visemes, with the worst pose; and the seconds each took. ``--every K`` fits
every K-th shape only (quicker); ``--ict`` adds ICT-FaceKit's head (folds and creases only:
its truth is not known).

``--found`` rigs each shaped face also from the landmarks found on its bare OBJ, as ``puppet rig``
does without ``--landmarks`` (``meshlandmarks.found_face``; needs the photo environment), and
prints instead of before and after: how sure the finding was, the found points' error against the
feature-point vertices (median and largest, % of the face width, as ``tools/checks/landmark_accuracy.py``
measures it), and the same figures for the rig **given** those vertices and the rig from the
landmarks **found** (both ``build_rig`` here; ICT's head, with ``--ict``, as without ``--found``).
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
from collections.abc import Callable
from pathlib import Path

import numpy as np

from puppet.bench.assets import shared_assets
from puppet.errors import PuppetError
from puppet.face.autorig import build_rig, rig_for_face
from puppet.face.default import default_face
from puppet.face.examples import load_examples
from puppet.face.load import load_face
from puppet.face.meshfile import load_mesh, write_bare_obj
from puppet.face.rig import Rig, load_rig
from puppet.photo.shapemodel import load_shape_model
from puppet.runtime.fapcalibration import fit_faps, relative_residual
from puppet.runtime.posecheck import pose_flaws
from puppet.runtime.runtime import Runtime
from puppet.view.meshlandmarks import found_face

ROOT = Path(__file__).resolve().parents[2]
BEFORE_RIG = """
import json, sys
from puppet.face.autorig import build_rig
from puppet.face.load import load_face
from puppet.face.rig import save_rig
mesh, landmarks, out = sys.argv[1:4]
save_rig(build_rig(load_face(mesh, landmarks=json.loads(landmarks))), out)
"""
"""The subprocess that rigs a mesh with another revision's package."""


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
    measure("before", face, lambda: before.rig(mesh, landmarks), reference, shapes)
    measure("after", face, lambda: transferred(face), reference, shapes)


def measure(name: str, face, rig: Callable[[], Rig], reference: Runtime, shapes: dict[str, np.ndarray] | None) -> None:
    """Print one line: the residual of ``face`` rigged by ``rig()`` (when ``shapes`` are given, in
    its face frame), its folds, creases and time; or why it could not be rigged, as ``puppet rig``
    would say it (found landmarks can be such: two control points on one place)."""
    start = time.perf_counter()
    try:
        runtime = Runtime(face, rig(), cache=False)
    except PuppetError as error:
        print(f"  {name:<8} not rigged: {error}")
        return
    rigged = time.perf_counter() - start
    residual = f"{median_residual(runtime, shapes):.3f}" if shapes else "  -  "
    print(f"  {name:<8} {residual}  {flaws(runtime, reference)}  "
          f"(rig {rigged:.1f} s, all {time.perf_counter() - start:.0f} s)")


def measure_found(given, mesh: Path, landmarks: dict[str, int], reference: Runtime,
                  shapes: dict[str, np.ndarray]) -> None:
    """``--found``: the landmarks found on ``mesh`` and their error against ``landmarks``, then the
    figures of ``given`` (the face from ``landmarks``) and of the face from the found landmarks."""
    start = time.perf_counter()
    bare = load_mesh(mesh)
    face, found = found_face(bare, str(mesh))
    print(f"  landmarks {found.summary()} ({time.perf_counter() - start:.0f} s)")
    print(f"  found vs given {found.error_summary(bare.vertices, landmarks)}")
    measure("given", given, lambda: transferred(given), reference, in_face_frame(given, shapes))
    measure("found", face, lambda: transferred(face), reference, in_face_frame(face, shapes))


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--faces", type=int, default=3, help="shaped faces (seeds 1..N)")
    parser.add_argument("--spread", type=float, default=2.0, help="shape weights' standard deviation")
    parser.add_argument("--every", type=int, default=1, help="fit every K-th ARKit shape only")
    parser.add_argument("--ict", action="store_true", help="add ICT-FaceKit's head (folds and creases)")
    parser.add_argument("--found", action="store_true",
                        help="rig from landmarks found on the bare mesh too (given vs found, not before vs after)")
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
            if args.found:
                measure_found(face, mesh, landmarks, reference, shapes)
            else:
                measure_ways(face, mesh, landmarks, before, reference, in_face_frame(face, shapes))
        from tools.figures.rig_faces import ict_inputs  # rig_faces draws a shaped face from here: imported late
        inputs = ict_inputs(shared_assets()) if args.ict else None
        if args.ict and inputs is None:
            print("ICT-FaceKit: not found, skipped")
        elif inputs is not None:
            print("ICT-FaceKit head (truth unknown: folds and creases only)")
            measure_ways(load_face(*inputs), *inputs, before, reference, None)


if __name__ == "__main__":
    main()
