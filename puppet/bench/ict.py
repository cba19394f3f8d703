"""The ICT-FaceKit head (read from ``../shared/assets``, never copied), auto-rigged for benchmarks.

The ICT head carries the 68 iBUG landmark vertices (``idx_to_landmark_verts`` in
``vertex_indices.json``); ``load_face(mesh, landmarks=...)`` turns them into MPEG-4 feature
points, parts (eyeballs, teeth, mouth socket, lashes) and contours (``puppet.face.landmarks``), and
``puppet.face.autorig`` rigs it the same way as the default face: functional regions, control points,
passive points, rigid parts and muscles. The benchmark measures that rig at ICT's resolution.
"""

from __future__ import annotations

import json
from pathlib import Path

from puppet.bench.assets import shared_assets
from puppet.face.autorig import build_rig
from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.face.rig import Rig


def ict_face_and_rig(root: Path | None = None) -> tuple[Face, Rig] | None:
    """The ICT face (in the face frame) and its auto-rig, or None when the assets are absent."""
    found = ict_inputs(root)
    if found is None:
        return None
    face = load_face(found[0], landmarks=found[1])
    face.name = "ict"
    return face, build_rig(face)


def ict_inputs(root: Path | None = None) -> tuple[Path, list[int]] | None:
    """The ICT mesh and its 68 iBUG landmark vertices, or None when the assets are absent."""
    folder = (root or shared_assets()) / "ict_facekit"
    mesh, indices = folder / "generic_neutral_mesh.obj", folder / "vertex_indices.json"
    if not (mesh.is_file() and indices.is_file()):
        return None
    return mesh, json.loads(indices.read_text())["idx_to_landmark_verts"]
