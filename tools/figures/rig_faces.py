"""Rig the ICT and MediaPipe faces from their landmarks and show the six expressions on each.

    PYTHONPATH=. .venv/bin/python tools/figures/rig_faces.py [--out docs/rig_contact_sheet.png] [--size 240]

Each face is rigged as a user rigs it: ``puppet rig MESH --landmarks L.json -o FOLDER`` (a
subprocess; its summary, times included, is printed), then read back with ``load_face(FOLDER)``.

* ICT-FaceKit (26,719 vertices): its 68 iBUG landmark vertices (``idx_to_landmark_verts`` in
  ``vertex_indices.json``).
* MediaPipe canonical face: its FDP candidates table (entries outside the 468-vertex mesh, the
  iris points, are left out: the face has no eyeballs).
* A face of another shape: the default face shaped by the shipped shape model (seed 1, two
  standard deviations; ``tools/checks/transfer_check.py``), written as a bare OBJ, landmarks its
  feature-point vertices.
* The default face, for comparison, with its shipped rig (first row).

Both assets are read from ``../shared/assets`` (``$FACEPUPPET_SHARED``); a missing one is skipped
with a note. The contact sheet has one row per face: neutral, then FAP 2 expressions 1..6 (joy,
sadness, anger, fear, disgust, surprise) at intensity 63, rendered headless (EGL).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from puppet.bench.assets import shared_assets
from puppet.face.autorig import rig_for_face
from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import SKIN_SRGB, Renderer, save_png, texture_kwargs
from tools.checks.transfer_check import shaped_face

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


def rigged_by_cli(mesh: Path, landmarks, folder: Path) -> Face:
    """The face folder ``puppet rig`` writes for ``mesh`` and ``landmarks``, read back; its
    summary is printed."""
    table = folder / "landmarks.json"
    table.write_text(json.dumps(landmarks))
    done = subprocess.run([sys.executable, "-m", "puppet.cli", "rig", str(mesh), "--landmarks", str(table),
                           "-o", str(folder / "face")], check=True, capture_output=True, text=True)
    print(done.stdout.rstrip())
    return load_face(folder / "face")


def drawn_triangles(face: Face) -> np.ndarray:
    """The face's triangles less the overlay shells over the eyes.

    ICT-FaceKit's eye occlusion and eye blend meshes (``attached`` parts) cover the whole eye
    opening; they are meant to be drawn translucent, and drawn opaque they hide the eyeballs (the
    sockets look empty). An attached component that lies in front of a pupil (3.5 / 3.6), the
    pupil inside one of its triangles seen from the front, is such a shell and is not drawn;
    lashes and tear lines pass beside the pupil and stay.
    """
    tri = np.asarray(face.triangles)
    attached = face.parts.get("attached")
    pupils = [np.asarray(face.feature_points[f], float) for f in ("3.5", "3.6") if f in face.feature_points]
    if attached is None or not len(attached) or not pupils:
        return tri
    v = np.asarray(face.vertices, float)
    mask = np.zeros(len(v), dtype=bool)
    mask[attached] = True
    own = tri[mask[tri].all(axis=1)]
    graph = sp.coo_matrix((np.ones(own.size), (own.ravel(), np.roll(own, 1, axis=1).ravel())), shape=(len(v),) * 2)
    _, comp = connected_components(graph, directed=False)
    hidden = set()
    a, b, c = (v[own[:, k], :2] for k in range(3))
    for pupil in pupils:
        p = pupil[:2]
        d1, d2, d3 = (_cross2(q - o, p - o) for o, q in ((a, b), (b, c), (c, a)))
        inside = ((d1 >= 0) & (d2 >= 0) & (d3 >= 0)) | ((d1 <= 0) & (d2 <= 0) & (d3 <= 0))
        front = v[own].mean(axis=1)[:, 2] >= pupil[2] - 1e-9 * np.ptp(v[:, 2])
        hidden |= set(comp[own[inside & front, 0]].tolist())
    if not hidden:
        return tri
    drop = np.zeros(len(v), dtype=bool)
    drop[attached] = np.isin(comp[attached], list(hidden))
    return tri[~drop[tri].any(axis=1)]


def vertex_colors(face: Face) -> np.ndarray | None:
    """The face's colours; a face without any (ICT) gets skin, and on its eyeballs a white
    sclera with a dark iris around the pupil (3.5 / 3.6), so that the eyes read as eyes."""
    if face.colors is not None or not any(p in face.parts for p in ("eye_l", "eye_r")):
        return face.colors
    v = np.asarray(face.vertices, float)
    colors = np.tile(np.asarray(SKIN_SRGB, float), (len(v), 1))
    for part, pupil in (("eye_l", "3.5"), ("eye_r", "3.6")):
        if part not in face.parts or pupil not in face.feature_points:
            continue
        eye = np.asarray(face.parts[part])
        p = np.asarray(face.feature_points[pupil], float)
        radius = np.linalg.norm(v[eye] - v[eye].mean(axis=0), axis=1).max()
        off = np.linalg.norm(v[eye] - p, axis=1) / radius
        colors[eye] = np.where(off[:, None] < 0.18, (0.05, 0.04, 0.04),
                               np.where(off[:, None] < 0.45, (0.35, 0.25, 0.15), (0.92, 0.90, 0.88)))
    return colors


def _cross2(u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """z of the cross product of 2-D vectors (rows)."""
    return u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]


def expression_row(face: Face, rig, size: int) -> np.ndarray:
    """Neutral and the six expressions side by side, framed on the face's deforming regions."""
    runtime = Runtime(face, rig, cache=False)
    front = np.concatenate([r.vertices for r in runtime.rig.regions if r.kind == "dffd"])
    poses = [runtime.deform_faps()] + [runtime.deform_faps(expression=(k, 63, 0, 0)) for k in range(1, 7)]
    with Renderer(drawn_triangles(face), len(face.vertices), vertex_colors(face), width=size, height=size,
                  **texture_kwargs(face)) as renderer:
        renderer.aim(face.vertices[front])
        return np.hstack([renderer.render(np.asarray(p, dtype=np.float32)) for p in poses])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/rig_contact_sheet.png")
    parser.add_argument("--size", type=int, default=240, help="tile size in pixels")
    args = parser.parse_args()
    assets = shared_assets()
    default = load_face()
    rows = [("default", default, rig_for_face(default))]
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        inputs = {"ict": ict_inputs(assets), "mediapipe": mediapipe_inputs(assets),
                  "shaped": shaped_face(scratch, seed=1, spread=2.0)}
        for name, given in inputs.items():
            if given is None:
                print(f"{name}: assets not found under {assets}, skipped")
                continue
            (scratch / name).mkdir()
            face = rigged_by_cli(*given, scratch / name)
            rows.append((name, face, rig_for_face(face)))
    sheet = np.vstack([expression_row(face, rig, args.size) for _, face, rig in rows])
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    save_png(sheet, args.out)
    print(f"contact sheet: {args.out} (rows {', '.join(n for n, _, _ in rows)}; columns neutral, "
          f"{', '.join(EXPRESSIONS)})")


if __name__ == "__main__":
    main()
