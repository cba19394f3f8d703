"""How close the landmarks ``puppet rig`` finds by itself come to landmarks given by hand.

    PYTHONPATH=. .venv/bin/python tools/checks/landmark_accuracy.py [--keep DIR]

For each face, the feature points found on its renders (``puppet.view.meshlandmarks``) are
compared with the ones it comes with, per MPEG-4 feature point both have, as the distance
between the two vertices in % of the face's width (MediaPipe's face-side points 234 to 454 as
found); the median and the largest, and the worst few by name:

* the embedded default face, written out as a bare OBJ: its own feature points;
* ICT-FaceKit: its 68 iBUG landmark vertices (``idx_to_landmark_verts``), as FDPs the way
  ``puppet.face.landmarks`` reads them (direct and halfway points; the rest it places itself and
  are no truth);
* MediaPipe's canonical face: its FDP candidates table (points on its 468 vertices).

The shared assets are read from ``../shared/assets`` (``$FACEPUPPET_SHARED``); a missing one is
skipped with a note. Needs the photo environment (MediaPipe).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from puppet.bench.assets import shared_assets
from puppet.face.default import default_face
from puppet.face.landmarks import IBUG_FDP, IBUG_MIDWAY, apply_landmarks
from puppet.face.meshfile import load_mesh, write_bare_obj
from puppet.view.meshlandmarks import find_landmarks
from tools.figures.rig_faces import ict_inputs, mediapipe_inputs


def truths(folder: Path) -> dict[str, tuple[Path, dict[str, int]]]:
    """Face name -> (its mesh, its given FDP -> vertex); missing assets left out with a note."""
    default = default_face()
    faces = {"default": (write_bare_obj(folder / "default.obj", default.vertices, default.triangles),
                         {f: int(v) for f, v in default.feature_vertices.items()})}
    assets = shared_assets()
    ict = ict_inputs(assets)
    if ict is None:
        print(f"ict: assets not found under {assets}, skipped")
    else:
        mesh, ibug = ict
        placed = apply_landmarks(load_mesh(mesh), ibug).feature_vertices
        faces["ict"] = (mesh, {f: int(placed[f]) for f in (*IBUG_FDP, *IBUG_MIDWAY)})
    mediapipe = mediapipe_inputs(assets)
    if mediapipe is None:
        print(f"mediapipe: assets not found under {assets}, skipped")
    else:
        faces["mediapipe"] = mediapipe
    return faces


def measure(name: str, mesh: Path, given: dict[str, int], keep: Path | None) -> None:
    """Find the landmarks on ``mesh`` and print their error against ``given``."""
    face = load_mesh(mesh)
    start = time.perf_counter()
    found = find_landmarks(face, str(mesh), keep=None if keep is None else keep / name)
    seconds = time.perf_counter() - start
    print(f"{name}: {len(face.vertices)} vertices, {found.summary()}; {seconds:.1f} s")
    print(f"  error {found.error_summary(face.vertices, given)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, default=None, help="a folder to keep the renders in")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        for name, (mesh, given) in truths(Path(scratch)).items():
            measure(name, mesh, given, args.keep)


if __name__ == "__main__":
    main()
