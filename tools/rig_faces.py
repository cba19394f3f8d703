"""Rig the ICT and MediaPipe faces from their landmarks and show the six expressions on each.

    PYTHONPATH=. .venv/bin/python tools/rig_faces.py [--out docs/rig_contact_sheet.png] [--size 240]

* ICT-FaceKit (26,719 vertices): its 68 iBUG landmark vertices (``idx_to_landmark_verts`` in
  ``vertex_indices.json``); the time to rig it (reading the mesh, landmarks to feature points,
  the rig, muscles included) is the median of 3 runs.
* MediaPipe canonical face: its FDP candidates table (entries outside the 468-vertex mesh, the
  iris points, are left out: the face has no eyeballs).
* The default face, for comparison, rigged from its own feature points.

Both assets are read from ``../shared/assets`` (``$FACEPUPPET_SHARED``); a missing one is skipped
with a note. The contact sheet has one row per face: neutral, then FAP 2 expressions 1..6 (joy,
sadness, anger, fear, disgust, surprise) at intensity 63, rendered headless (EGL).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from puppet.autorig import build_rig
from puppet.bench import shared_assets
from puppet.face import Face, load_face
from puppet.render import Renderer, save_png, texture_kwargs
from puppet.runtime import Runtime

EXPRESSIONS = ("joy", "sadness", "anger", "fear", "disgust", "surprise")


def ict_inputs(assets: Path) -> tuple[Path, list[int]] | None:
    """The ICT mesh and its 68 iBUG landmark vertices, or None when absent."""
    folder = assets / "ict_facekit"
    mesh, indices = folder / "generic_neutral_mesh.obj", folder / "vertex_indices.json"
    if not (mesh.is_file() and indices.is_file()):
        return None
    return mesh, json.loads(indices.read_text())["idx_to_landmark_verts"]


def mediapipe_inputs(assets: Path) -> tuple[Path, dict[str, int]] | None:
    """The MediaPipe mesh and its FDP table (points on its vertices), or None when absent."""
    folder = assets / "mediapipe_face"
    mesh, table = folder / "mediapipe_canonical_face_model.obj", folder / "mediapipe_mpeg4_fdp_candidates.json"
    if not (mesh.is_file() and table.is_file()):
        return None
    n = sum(1 for line in mesh.read_text().splitlines() if line.startswith("v "))
    points = json.loads(table.read_text())["points"]
    return mesh, {fid: p["index"] for fid, p in points.items() if p["index"] < n}


def rig_time(mesh: Path, landmarks, runs: int = 3) -> float:
    """Median seconds to read, landmark and rig a face."""
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        build_rig(load_face(mesh, landmarks=landmarks))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def expression_row(face: Face, size: int) -> np.ndarray:
    """Neutral and the six expressions side by side, framed on the face's deforming regions."""
    runtime = Runtime(face, build_rig(face), cache=False)
    front = np.concatenate([r.vertices for r in runtime.rig.regions if r.kind == "dffd"])
    poses = [runtime.pose()] + [runtime.pose(expression=(k, 63, 0, 0)) for k in range(1, 7)]
    with Renderer(face.triangles, len(face.vertices), face.colors, width=size, height=size,
                  **texture_kwargs(face)) as renderer:
        renderer.frame(face.vertices[front])
        return np.hstack([renderer.render(np.asarray(p, dtype=np.float32)) for p in poses])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/rig_contact_sheet.png")
    parser.add_argument("--size", type=int, default=240, help="tile size in pixels")
    args = parser.parse_args()
    assets = shared_assets()
    rows = [("default", load_face())]
    for name, inputs in (("ict", ict_inputs(assets)), ("mediapipe", mediapipe_inputs(assets))):
        if inputs is None:
            print(f"{name}: assets not found under {assets}, skipped")
            continue
        mesh, landmarks = inputs
        face = load_face(mesh, landmarks=landmarks)
        rig = build_rig(face)
        print(f"{name}: {len(face.vertices)} vertices, {len(rig.regions)} regions, "
              f"{len(rig.control_points)} control points, {len(getattr(rig, 'muscles', []))} muscles; "
              f"rig time (read + landmarks + rig, median of 3) {rig_time(mesh, landmarks):.2f} s")
        rows.append((name, face))
    sheet = np.vstack([expression_row(face, args.size) for _, face in rows])
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    save_png(sheet, args.out)
    print(f"contact sheet: {args.out} (rows {', '.join(n for n, _ in rows)}; columns neutral, "
          f"{', '.join(EXPRESSIONS)})")


if __name__ == "__main__":
    main()
