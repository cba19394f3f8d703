"""The landmark picker on a mesh: its feature points shown on a front render, dragged to where
they belong, saved as the landmark JSON ``puppet rig --landmarks`` takes ({FDP id: vertex}).

The points start where ``puppet rig`` found them (``puppet.view.meshlandmarks``), or from a
landmark file (``--start``: the ``landmarks.json`` rig wrote, any {FDP id: vertex} file, or the 68
iBUG vertices). The mesh is turned to face the camera (the rotation that fits those points to the
default face's) and rendered from the front, framed on them; the page is the photo picker's
(``puppet.view.picker``: zoom, pan, drag), each point labelled with its FDP id.

On save, a point that was moved is lifted through the render: the surface seen at its pixel
(``SurfacePass``), snapped to the nearest skin vertex (the component the points lie on); a point
left where it was keeps its vertex (a point hidden from the front, as an inner lip point behind
closed lips, stays itself). A point dragged off the mesh is refused (HTTP 400, the page says why).
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from puppet.face.default import default_face
from puppet.face.landmarks import IBUG_FDP, IBUG_MIDWAY, LandmarkError, apply_landmarks, read_landmarks
from puppet.face.meshfile import load_mesh
from puppet.view.meshlandmarks import Shots, find_landmarks, fit_rotation, project, skin_vertices
from puppet.view.picker import PickerServer
from puppet.view.renderer import save_png

SIZE = 768  # pixels, the square front render
SHARE = 0.6  # of the image the feature points span
MOVED = 0.5  # pixels: a point moved less is left on its vertex
HINT = ("drag any feature point that is off its place on the rendered mesh (labelled with its MPEG-4 id: "
        "3.x eyes, 4.x brows, 8.x outer lips, 2.x inner lips, chin and jaw, 9.x nose, 5.x cheeks, 10.x ears, "
        "11.x hairline)")


class MeshPickerServer(PickerServer):
    """The picker's web server for one mesh; ``wait`` returns the saved landmark file. ``start``:
    a landmark file, dict or iBUG list to start from; None finds them (the photo set-up)."""

    def __init__(self, mesh: str | os.PathLike, out: str | os.PathLike, port: int = 0,
                 start: str | os.PathLike | dict | list | None = None, size: int = SIZE) -> None:
        face = load_mesh(mesh)
        self.vertices = np.asarray(face.vertices, float)
        self.fdp = start_points(face, mesh, start)
        ids = list(self.fdp)
        marked = self.vertices[[self.fdp[f] for f in ids]]
        reference = default_face().feature_points
        known = [f for f in ids if f in reference]
        rotation = fit_rotation(self.vertices[[self.fdp[f] for f in known]], np.array([reference[f] for f in known]))
        self._scratch = tempfile.TemporaryDirectory(prefix="puppet-pick-")
        with Shots(face, size) as shots:
            self.camera = shots.framing(rotation, marked, SHARE)
            image, self.surface = shots.shoot(self.camera)
        self.photo, self.layout, self.out = Path(self._scratch.name) / "front.png", "mesh", Path(out)
        self.size = (size, size)
        save_png(image, self.photo)
        self.start = project(self.camera, marked, self.size).tolist()
        self.skin = skin_vertices(self.vertices, face.triangles, marked[None])
        self.hints, self.dragged, self.labels = [HINT], True, ids
        self._serve(port)

    def save(self, body: bytes) -> str:
        """Check the POSTed points (one per feature point, inside the render, on the mesh), lift
        the moved ones onto the mesh and write {FDP id: vertex}; raises ``LandmarkError``."""
        try:
            data = json.loads(body)
        except json.JSONDecodeError as exc:
            raise LandmarkError(f"not JSON: {exc}") from None
        points = data.get("points") if isinstance(data, dict) else data
        try:
            xy = np.array([p[:2] for p in points], dtype=float).reshape(-1, 2)
        except (TypeError, ValueError, IndexError):
            raise LandmarkError("expected points as a list of [x, y] pixels") from None
        if len(xy) != len(self.labels):
            raise LandmarkError(f"expected {len(self.labels)} points (one per feature point), got {len(xy)}")
        marks = {fid: self._vertex(fid, p, q) for fid, p, q in zip(self.labels, xy, np.array(self.start))}
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.out.write_text(json.dumps(marks, indent=1) + "\n", encoding="utf-8")
        self.saved.set()
        return f"saved {len(marks)} feature points to {self.out}"

    def _vertex(self, fid: str, pixel: np.ndarray, start: np.ndarray) -> int:
        """The vertex of a point at ``pixel`` that started at ``start``: its own if not moved, else
        the skin vertex nearest the surface seen there."""
        if np.linalg.norm(pixel - start) < MOVED:
            return self.fdp[fid]
        col, row = int(np.floor(pixel[0])), int(np.floor(pixel[1]))
        if not (0 <= col < self.size[0] and 0 <= row < self.size[1]) or not np.isfinite(self.surface[row, col]).all():
            raise LandmarkError(f"FDP {fid} at pixel ({pixel[0]:.0f}, {pixel[1]:.0f}) is off the mesh")
        skin = self.vertices[self.skin]
        return int(self.skin[cKDTree(skin).query(self.surface[row, col])[1]])

    def close(self) -> None:
        super().close()
        self._scratch.cleanup()


def start_points(face, mesh: str | os.PathLike, start) -> dict[str, int]:
    """{FDP id: vertex} to start from: found on the mesh (``start`` None), read from a landmark
    file or dict, or an iBUG 68 list read as the FDPs it gives (``puppet.face.landmarks``)."""
    if start is None:
        return find_landmarks(face, str(mesh)).fdp
    given = read_landmarks(start, len(face.vertices))
    if isinstance(given, dict):
        return given
    placed = apply_landmarks(face, given).feature_vertices
    return {fid: int(placed[fid]) for fid in (*IBUG_FDP, *IBUG_MIDWAY)}
