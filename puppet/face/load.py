"""``load_face``: a face from wherever it comes: the embedded default, a mesh file (made rig-ready
by its landmarks), or a face folder."""

from __future__ import annotations

import os
from pathlib import Path

from puppet.face.default import default_face
from puppet.face.folder import load_face_folder
from puppet.face.landmarks import apply_landmarks
from puppet.face.meshfile import load_mesh
from puppet.face.model import Face


def load_face(path: str | os.PathLike | None = None, landmarks=None) -> Face:
    """The embedded default face (``path`` None), or the mesh at ``path`` in file vertex order.

    ``landmarks`` (a JSON path, a dict {FDP id: vertex} or a list of 68 iBUG vertices) makes the
    mesh rig-ready: face frame, parts, contours, pivots and feature points (``puppet.face.landmarks``).
    A folder is a face folder (``puppet.face.folder``: a face built from a photo, textured).
    """
    if path is None:
        return default_face()
    if Path(path).is_dir():
        return load_face_folder(path)
    face = load_mesh(path)
    return face if landmarks is None else apply_landmarks(face, landmarks)
