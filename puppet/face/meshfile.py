"""Face meshes from files, in file vertex order.

OBJ files are parsed here, in file order (a loader that splits vertices at UV seams would
renumber them, and landmark tables index the file's vertices); polygons are fan-triangulated.
Other formats go through trimesh with ``process=False``; the geometries of a scene are merged in
order. Such a face has one part, ``skin``, and no feature points: ``puppet.face.landmarks`` gives
it them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from puppet.face.model import Face, FaceFileError


def load_mesh(path: str | os.PathLike) -> Face:
    """The mesh at ``path`` as a one-part face (``skin``) without feature points."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"face mesh {str(path)!r} does not exist")
    if not path.is_file():
        raise FaceFileError(f"face mesh {str(path)!r} is not a file")
    if path.suffix.lower() == ".obj":
        mesh = read_obj(path)
        positions, triangles, tri_uv = mesh.triangulated()
        uv = mesh.uvs.astype(np.float32) if tri_uv is not None else None
        colors = mesh.colors
    else:
        positions, triangles, uv, tri_uv, colors = _read_with_trimesh(path)
    if len(triangles) == 0:
        raise FaceFileError(f"face mesh {str(path)!r} has no faces")
    return Face(
        name=path.stem,
        vertices=positions,
        triangles=triangles,
        parts={"skin": np.arange(len(positions), dtype=np.int32)},
        colors=colors,
        uv=uv,
        triangle_uv=tri_uv,
    )



@dataclass
class ObjMesh:
    """An OBJ file as written: vertices and polygons in file order (0-based indices)."""

    positions: np.ndarray  # (N, 3) float64
    uvs: np.ndarray  # (T, 2) float64
    polygons: list[list[int]]  # vertex indices per polygon
    polygon_uvs: list[list[int] | None]  # uv indices per polygon corner, None where it has none
    groups: list[str | None]  # the 'g' group each polygon was in
    colors: np.ndarray | None = None  # (N, 3) float32 when every 'v' line carries r g b

    def triangulated(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(positions, triangles (F, 3) int32, triangle_uv (F, 3) int32 or None): polygons
        fan-triangulated from their first corner, so a quad a b c d gives a b c and a c d."""
        tris, tri_uv = [], []
        has_uv = all(p is not None for p in self.polygon_uvs) and len(self.uvs) > 0
        for poly, puv in zip(self.polygons, self.polygon_uvs):
            for k in range(1, len(poly) - 1):
                tris.append((poly[0], poly[k], poly[k + 1]))
                if has_uv:
                    tri_uv.append((puv[0], puv[k], puv[k + 1]))
        triangles = np.array(tris, dtype=np.int32).reshape(-1, 3)
        uv = np.array(tri_uv, dtype=np.int32).reshape(-1, 3) if has_uv else None
        return self.positions, triangles, uv


def read_obj(path: str | os.PathLike) -> ObjMesh:
    """Parse an OBJ file's v, vt, f (and g) lines in file order; normals and materials are
    ignored. Indices may be negative (relative). Errors name the file and line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise FaceFileError(f"cannot read face mesh {str(path)!r}: {exc.strerror or exc}") from exc
    positions: list[list[float]] = []
    colors: list[list[float]] = []
    uvs: list[list[float]] = []
    polygons: list[list[int]] = []
    polygon_uvs: list[list[int] | None] = []
    groups: list[str | None] = []
    group = None
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        tag = parts[0]
        try:
            if tag == "v":
                values = [float(x) for x in parts[1:]]
                if len(values) < 3:
                    raise ValueError("a vertex needs x y z")
                positions.append(values[:3])
                if len(values) >= 6:  # the common "v x y z r g b" extension
                    colors.append(values[3:6])
            elif tag == "vt":
                values = [float(x) for x in parts[1:3]]
                if not values:
                    raise ValueError("a texture coordinate needs u")
                uvs.append(values + [0.0] * (2 - len(values)))
            elif tag == "f":
                corners = parts[1:]
                if len(corners) < 3:
                    raise ValueError(f"a face needs 3 or more corners, got {len(corners)}")
                vi, ti = [], []
                for corner in corners:
                    fields = corner.split("/")
                    vi.append(_obj_index(fields[0], len(positions), "vertex"))
                    if len(fields) > 1 and fields[1]:
                        ti.append(_obj_index(fields[1], len(uvs), "texture coordinate"))
                polygons.append(vi)
                polygon_uvs.append(ti if len(ti) == len(vi) else None)
                groups.append(group)
            elif tag == "g":
                group = " ".join(parts[1:]) or None
        except ValueError as exc:
            raise FaceFileError(f"{path}:{lineno}: {exc}: {line.strip()[:80]!r}") from None
    if not positions:
        raise FaceFileError(f"face mesh {str(path)!r} has no vertices ('v' lines)")
    color_array = None
    if colors and len(colors) == len(positions):
        c = np.array(colors, dtype=np.float32)
        color_array = c / 255.0 if c.max(initial=0.0) > 1.0 else c
    return ObjMesh(
        positions=np.array(positions, dtype=np.float64),
        uvs=np.array(uvs, dtype=np.float64).reshape(-1, 2),
        polygons=polygons,
        polygon_uvs=polygon_uvs,
        groups=groups,
        colors=color_array,
    )


def _obj_index(token: str, count: int, what: str) -> int:
    """A 1-based (or negative, relative) OBJ index as a 0-based index, checked against count."""
    i = int(token)
    if i == 0:
        raise ValueError(f"{what} index 0 (OBJ indices start at 1)")
    j = i - 1 if i > 0 else count + i
    if not 0 <= j < count:
        raise ValueError(f"{what} index {i} out of range (only {count} defined so far)")
    return j


# -- other formats through trimesh ---------------------------------------------------------------

def _read_with_trimesh(path: Path):
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, maintain_order=True)
    except Exception as exc:  # trimesh raises many kinds; name the file either way
        raise FaceFileError(f"cannot read face mesh {str(path)!r}: {type(exc).__name__}: {exc}") from exc
    if isinstance(loaded, trimesh.Scene):
        meshes = _scene_meshes(loaded)
    else:
        meshes = [loaded]
    meshes = [m for m in meshes if isinstance(m, trimesh.Trimesh)]
    if not meshes:
        raise FaceFileError(f"face mesh {str(path)!r} holds no triangle mesh")
    positions, triangles, uvs, colors = [], [], [], []
    offset = 0
    for m in meshes:
        positions.append(np.asarray(m.vertices, dtype=np.float64))
        triangles.append(np.asarray(m.faces, dtype=np.int64) + offset)
        offset += len(m.vertices)
        visual = getattr(m, "visual", None)
        uv = getattr(visual, "uv", None) if visual is not None and visual.kind == "texture" else None
        uvs.append(None if uv is None or len(uv) != len(m.vertices) else np.asarray(uv, np.float32))
        vc = None
        if visual is not None and visual.kind == "vertex":
            vc = np.asarray(visual.vertex_colors, dtype=np.float32)[:, :3] / 255.0
        colors.append(vc)
    vertices = np.vstack(positions)
    tris = np.vstack(triangles).astype(np.int32)
    uv = np.vstack(uvs).astype(np.float32) if all(u is not None for u in uvs) else None
    tri_uv = tris.copy() if uv is not None else None
    color = np.vstack(colors).astype(np.float32) if all(c is not None for c in colors) else None
    return vertices, tris, uv, tri_uv, color


def _scene_meshes(scene) -> list:
    """The scene's geometries in file order, each placed by the node transform(s) that use it."""
    out = []
    for name, geometry in scene.geometry.items():
        nodes = scene.graph.geometry_nodes.get(name, [])
        if not nodes:
            out.append(geometry)
        for node in nodes:
            transform, _ = scene.graph[node]
            placed = geometry.copy()
            placed.apply_transform(transform)
            out.append(placed)
    return out
