"""Face meshes from files, in file vertex order, with their parts and colours.

OBJ files are parsed here, in file order (a loader that splits vertices at UV seams would
renumber them, and landmark tables index the file's vertices); polygons are fan-triangulated.
Their ``mtllib`` materials colour them: each polygon's ``usemtl`` material gives its vertices its
``Kd`` (as written, read as sRGB) unless the ``v`` lines carry colours, and a ``map_Kd`` image
textures them (per vertex uv: at a uv seam a vertex keeps one of its corners' uv). A missing
.mtl or image leaves the colours out, as most viewers do.

glTF, GLB and VRM files are read by ``puppet.face.gltfread``: every primitive in scene order,
vertex for vertex, coloured by its material, textured by its base-colour texture.

Several textures become one atlas (``puppet.face.atlas``), so the renderer keeps one texture.
The pieces a file is made of (glTF primitives, OBJ groups and materials) name the face's parts
(``puppet.face.meshparts``: eyeballs, teeth, tongue, lashes; the rest skin); an OBJ with neither
groups nor materials is one part, ``skin``. Other formats go through trimesh with
``process=False``, the geometries of a scene merged in order into one part. No loaded face has
feature points: ``puppet.face.landmarks`` gives it them.

``write_bare_obj`` goes the other way: a mesh as a user's exporter gives it at its barest,
positions and triangles only (tools and tests make users' meshes with it).
"""

from __future__ import annotations

import itertools
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from PIL import Image, UnidentifiedImageError

from puppet.face.atlas import pack, place_uv
from puppet.face.gltfread import MAX_BYTES, MAX_VERTICES, read_gltf
from puppet.face.meshparts import Piece, cornea_vertices, name_parts, overlay_vertices
from puppet.face.model import Face, FaceFileError, TexturedFace
from puppet.face.objbulk import read_bulk

GLTF_SUFFIXES = (".glb", ".gltf", ".vrm")


def load_mesh(path: str | os.PathLike) -> Face:
    """The mesh at ``path`` as a face without feature points, its parts named from its pieces and
    coloured as its materials say (module docstring); a :class:`TexturedFace` when textured."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"face mesh {str(path)!r} does not exist")
    if not path.is_file():
        raise FaceFileError(f"face mesh {str(path)!r} is not a file")
    suffix = path.suffix.lower()
    if suffix == ".obj":
        face = _obj_face(path)
    elif suffix in GLTF_SUFFIXES:
        face = _gltf_face(path)
    else:
        positions, triangles, uv, tri_uv, colors = _read_with_trimesh(path)
        face = Face(name=path.stem, vertices=positions, triangles=triangles,
                    parts={"skin": np.arange(len(positions), dtype=np.int32)}, colors=colors, uv=uv,
                    triangle_uv=tri_uv)
    if len(face.triangles) == 0:
        raise FaceFileError(f"face mesh {str(path)!r} has no faces")
    return face


def _obj_face(path: Path) -> Face:
    """An OBJ file as a face: parts from its groups and materials, colours and texture from its MTL."""
    mesh = read_obj(path)
    positions, triangles, tri_uv = mesh.triangulated()
    polygon_of = mesh.triangle_polygons()
    keys = [f"{g or ''} {m or ''}".strip() for g, m in zip(mesh.groups, mesh.materials)]
    parts = {"skin": np.arange(len(positions), dtype=np.int32)}
    if any(keys):
        pieces = [Piece(key, np.unique(triangles[np.isin(polygon_of, idx)]))
                  for key, idx in _indices_by_key(keys).items()]
        pieces = [p for p in pieces if len(p.vertices)]
        parts = name_parts(positions, triangles, pieces)
        keep = _drawn(triangles, pieces, parts, positions)
        triangles, polygon_of = triangles[keep], polygon_of[keep]
        tri_uv = tri_uv[keep] if tri_uv is not None else None
    materials = _obj_materials(path, mesh)
    colors = mesh.colors
    if colors is None and materials:
        colors = _obj_colors(len(positions), triangles, polygon_of, mesh.materials, materials)
    textured = _obj_texture(len(positions), triangles, tri_uv, mesh, polygon_of, materials)
    face_uv = mesh.uvs.astype(np.float32) if tri_uv is not None else None
    if textured is None:
        return Face(name=path.stem, vertices=positions, triangles=triangles, parts=parts, colors=colors,
                    uv=face_uv, triangle_uv=tri_uv)
    return TexturedFace(name=path.stem, vertices=positions, triangles=triangles, parts=parts, colors=colors,
                        triangle_uv=triangles.copy(), **textured)


def _drawn(triangles: np.ndarray, pieces: list[Piece], parts: dict[str, np.ndarray],
           vertices: np.ndarray) -> np.ndarray:
    """Per triangle, whether it is kept: those of see-through overlays and cornea caps are not
    (``meshparts.overlay_vertices``, ``cornea_vertices``); their vertices stay, so vertex indices hold."""
    overlay = overlay_vertices(len(vertices), pieces) | cornea_vertices(vertices, pieces)
    overlay[parts.get("skin", [])] = False
    return ~overlay[triangles].all(axis=1)


def _indices_by_key(keys: list[str]) -> dict[str, np.ndarray]:
    """{key: the positions it holds in ``keys``}, keys in first-seen order."""
    out: dict[str, list[int]] = {}
    for i, key in enumerate(keys):
        out.setdefault(key, []).append(i)
    return {k: np.array(v) for k, v in out.items()}


def _obj_materials(path: Path, mesh: ObjMesh) -> dict[str, dict]:
    """{material: {"Kd": rgb, "map_Kd": image or None}} from the OBJ's mtllib files that exist."""
    out: dict[str, dict] = {}
    for name in mesh.mtllibs:
        mtl = path.parent / name
        if mtl.is_file():
            out |= read_mtl(mtl)
    return out


def read_mtl(path: str | os.PathLike) -> dict[str, dict]:
    """An MTL file's materials: {name: {"Kd": (3,) float32 or None, "map_Kd": (H, W, 3) uint8 or
    None}}; a ``map_Kd`` image that is missing or unreadable is left out."""
    path = Path(path)
    out: dict[str, dict] = {}
    current = None
    for lineno, line in enumerate(path.read_text("utf-8", errors="replace").splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if fields[0] == "newmtl":
            current = out.setdefault(" ".join(fields[1:]), {"Kd": None, "map_Kd": None})
        elif current is not None and fields[0] == "Kd" and len(fields) >= 4:
            try:
                current["Kd"] = np.clip(np.array(fields[1:4], dtype=np.float32), 0.0, 1.0)
            except ValueError:
                raise FaceFileError(f"{path}:{lineno}: Kd needs three numbers: {line.strip()[:60]!r}") from None
        elif current is not None and fields[0] == "map_Kd" and len(fields) >= 2:
            current["map_Kd"] = _image_or_none(path.parent / fields[-1])
    return out


def _image_or_none(path: Path) -> np.ndarray | None:
    try:
        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"), dtype=np.uint8)
    except (OSError, UnidentifiedImageError, ValueError):
        return None


def _obj_colors(n: int, triangles: np.ndarray, polygon_of: np.ndarray, names: list[str | None],
                materials: dict[str, dict]) -> np.ndarray | None:
    """Per vertex the Kd of the material of a polygon that uses it (white where none says)."""
    kd = {name: m["Kd"] for name, m in materials.items() if m["Kd"] is not None}
    if not kd:
        return None
    table = np.array([kd.get(name, (1.0, 1.0, 1.0)) for name in names], dtype=np.float32).reshape(-1, 3)
    colors = np.ones((n, 3), dtype=np.float32)
    colors[triangles.ravel()] = np.repeat(table[polygon_of], 3, axis=0)
    return colors


def _obj_texture(n: int, triangles: np.ndarray, tri_uv: np.ndarray | None, mesh: ObjMesh, polygon_of: np.ndarray,
                 materials: dict[str, dict]) -> dict | None:
    """uv, texture and texture_weight of an OBJ whose materials have map_Kd images, else None."""
    images = {name: m["map_Kd"] for name, m in materials.items() if m["map_Kd"] is not None}
    if not images or tri_uv is None:
        return None
    names = sorted(images)
    atlas, places = pack([images[k] for k in names])
    uv, weight = np.zeros((n, 2), dtype=np.float32), np.zeros(n, dtype=np.float32)
    polygon_material = np.array([m or "" for m in mesh.materials], dtype=object)[polygon_of]
    for name, place in zip(names, places):
        rows = polygon_material == name
        corner_uv = mesh.uvs[tri_uv[rows].ravel()] * [1.0, -1.0] + [0.0, 1.0]  # to glTF's v down
        uv[triangles[rows].ravel()] = place_uv(corner_uv, place)
        weight[triangles[rows].ravel()] = 1.0
    return {"uv": uv, "texture": atlas, "texture_weight": weight}


def _gltf_face(path: Path) -> Face:
    """A glTF / GLB / VRM file's primitives as one face, vertex for vertex in scene order."""
    scene = read_gltf(path)
    if not scene.pieces:
        raise FaceFileError(f"face mesh {str(path)!r} holds no triangle mesh")
    sizes = [len(p.positions) for p in scene.pieces]
    starts = np.cumsum([0] + sizes)
    vertices = np.vstack([p.positions for p in scene.pieces])
    triangles = np.vstack([p.triangles + s for p, s in zip(scene.pieces, starts)]).astype(np.int32)
    pieces = [Piece(" ".join(p.names), np.arange(s, s + k)) for p, s, k in zip(scene.pieces, starts, sizes)]
    parts = name_parts(vertices, triangles, pieces)
    triangles = triangles[_drawn(triangles, pieces, parts, vertices)]
    colors = None
    if any(p.colors is not None or p.texture is not None for p in scene.pieces):
        colors = np.vstack([p.colors if p.colors is not None else np.ones((len(p.positions), 3), np.float32)
                            for p in scene.pieces]).astype(np.float32)
    textured = [(p, s) for p, s in zip(scene.pieces, starts) if p.texture is not None and p.uv is not None]
    if not textured:
        return Face(name=path.stem, vertices=vertices, triangles=triangles, parts=parts, colors=colors)
    images = list({id(p.texture): p.texture for p, _ in textured}.values())
    atlas, places = pack(images)
    place_of = {id(im): place for im, place in zip(images, places)}
    uv, weight = np.zeros((len(vertices), 2), dtype=np.float32), np.zeros(len(vertices), dtype=np.float32)
    for p, s in textured:
        uv[s:s + len(p.uv)] = place_uv(p.uv, place_of[id(p.texture)])
        weight[s:s + len(p.uv)] = 1.0
    return TexturedFace(name=path.stem, vertices=vertices, triangles=triangles, parts=parts, colors=colors,
                        uv=uv, triangle_uv=triangles.copy(), texture=atlas, texture_weight=weight)


def write_bare_obj(path: str | os.PathLike, vertices: np.ndarray, triangles: np.ndarray) -> Path:
    """An OBJ of ``vertices`` (v lines, written to read back exactly) and ``triangles`` (f lines,
    0-based here, 1-based there) and nothing else: no groups, materials, uv or normals. Returns its path."""
    path = Path(path)
    path.write_text(obj_lines("v %.17g %.17g %.17g", vertices) + obj_lines("f %d %d %d", np.asarray(triangles) + 1))
    return path


def obj_lines(fmt: str, rows: np.ndarray) -> str:
    """One line per row of ``rows``, each ``fmt`` % the row, newline-ended: numpy's ``savetxt``
    in one formatting step (it formats row by row: a third of the time to write ICT's face.obj)."""
    rows = np.asarray(rows)
    return ((fmt + "\n") * len(rows)) % tuple(rows.ravel().tolist())


@dataclass
class ObjMesh:
    """An OBJ file as written: vertices and polygons in file order (0-based indices), the polygons'
    corners one after another (``starts``), as numpy arrays so that large files read in a blink."""

    positions: np.ndarray  # (N, 3) float64
    uvs: np.ndarray  # (T, 2) float64
    corners: np.ndarray  # (C,) int64 vertex index of each polygon corner, polygon after polygon
    corner_uvs: np.ndarray  # (C,) int64 uv index of each corner, -1 where its polygon has none
    starts: np.ndarray  # (P + 1,) int64 where each polygon's corners start (and the end)
    groups: list[str | None]  # the 'g' group each polygon was in
    colors: np.ndarray | None = None  # (N, 3) float32 when every 'v' line carries r g b
    materials: list[str | None] = field(default_factory=list)  # the 'usemtl' material of each polygon
    mtllibs: list[str] = field(default_factory=list)  # the 'mtllib' files named, in order

    @property
    def polygons(self) -> list[list[int]]:
        """Vertex indices per polygon."""
        return _split(self.corners, self.starts)

    @property
    def polygon_uvs(self) -> list[list[int] | None]:
        """uv indices per polygon corner, None where the polygon has none."""
        return [None if uv and uv[0] < 0 else uv for uv in _split(self.corner_uvs, self.starts)]

    def triangle_polygons(self) -> np.ndarray:
        """The polygon each of ``triangulated``'s triangles comes from (F,)."""
        return np.repeat(np.arange(len(self.starts) - 1), np.diff(self.starts) - 2)

    def triangulated(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(positions, triangles (F, 3) int32, triangle_uv (F, 3) int32 or None): polygons
        fan-triangulated from their first corner, so a quad a b c d gives a b c and a c d."""
        polygon = self.triangle_polygons()
        first = self.starts[polygon]
        k = np.arange(len(polygon)) - np.searchsorted(polygon, polygon) + 1
        at = np.stack([first, first + k, first + k + 1], axis=1)
        has_uv = len(self.uvs) > 0 and bool((self.corner_uvs >= 0).all())
        uv = self.corner_uvs[at].astype(np.int32) if has_uv else None
        return self.positions, self.corners[at].astype(np.int32).reshape(-1, 3), uv


def read_obj(path: str | os.PathLike) -> ObjMesh:
    """Parse an OBJ file's v, vt, f (and g, usemtl, mtllib) lines in file order; normals are
    ignored. Indices may be negative (relative). Errors name the file and line."""
    path = Path(path)
    try:
        _check_bytes(path)
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise FaceFileError(f"cannot read face mesh {str(path)!r}: {exc.strerror or exc}") from exc
    _check_vertices(path, len(re.findall(r"^[ \t]*v[ \t]", text, flags=re.MULTILINE)))
    bulk = read_bulk(text)
    if bulk is not None:
        return ObjMesh(positions=bulk.positions, uvs=bulk.uvs, corners=bulk.corners, corner_uvs=bulk.corner_uvs,
                       starts=bulk.starts, groups=bulk.groups, colors=_colors(bulk.colors), materials=bulk.materials,
                       mtllibs=bulk.mtllibs)
    return _read_lines(path, text)


def _read_lines(path: Path, text: str) -> ObjMesh:
    """``read_obj`` line by line: any OBJ it reads, and the line of the first mistake."""
    positions: list[list[float]] = []
    colors: list[list[float]] = []
    uvs: list[list[float]] = []
    polygons: list[_Polygon] = []
    groups: list[str | None] = []
    materials: list[str | None] = []
    mtllibs: list[str] = []
    group = material = None
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
                polygons.append(_polygon(lineno, line, parts[1:], len(positions), len(uvs)))
                groups.append(group)
                materials.append(material)
            elif tag == "g":
                group = " ".join(parts[1:]) or None
            elif tag == "usemtl":
                material = " ".join(parts[1:]) or None
            elif tag == "mtllib":
                mtllibs.append(" ".join(parts[1:]))
        except ValueError as exc:
            raise FaceFileError(f"{path}:{lineno}: {exc}: {line.strip()[:80]!r}") from None
    if not positions:
        raise FaceFileError(f"face mesh {str(path)!r} has no vertices ('v' lines)")
    color_array = _colors(np.array(colors, dtype=np.float32)) if colors and len(colors) == len(positions) else None
    starts = np.concatenate([[0], np.cumsum([len(p.vertices) for p in polygons], dtype=np.int64)])
    return ObjMesh(
        positions=np.array(positions, dtype=np.float64),
        uvs=np.array(uvs, dtype=np.float64).reshape(-1, 2),
        corners=_resolved(path, polygons, starts, "vertex"),
        corner_uvs=_resolved(path, polygons, starts, "texture coordinate"),
        starts=starts,
        groups=groups,
        colors=color_array,
        materials=materials,
        mtllibs=mtllibs,
    )


def _colors(colors: np.ndarray | None) -> np.ndarray | None:
    """Vertex colours as 0-1 floats: written as 0-255 where any exceeds 1."""
    if colors is None:
        return None
    return colors / 255.0 if colors.max(initial=0.0) > 1.0 else colors


class _Polygon(NamedTuple):
    """An 'f' line as written: its OBJ indices (1-based or negative) and the counts they are
    relative to (the vertices and texture coordinates defined before it)."""

    lineno: int
    line: str
    vertices: list[int]
    uvs: list[int] | None
    vertex_count: int
    uv_count: int


def _polygon(lineno: int, line: str, corners: list[str], vertex_count: int, uv_count: int) -> _Polygon:
    """An 'f' line's corners ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` (uvs kept when every corner has one)."""
    if len(corners) < 3:
        raise ValueError(f"a face needs 3 or more corners, got {len(corners)}")
    fields = [corner.split("/") for corner in corners]
    uvs = [int(f[1]) for f in fields if len(f) > 1 and f[1]]
    return _Polygon(lineno, line, [int(f[0]) for f in fields], uvs if len(uvs) == len(fields) else None,
                    vertex_count, uv_count)


def _resolved(path: Path, polygons: list[_Polygon], starts: np.ndarray, what: str) -> np.ndarray:
    """The polygons' corner indices of ``what`` (vertex or texture coordinate) 0-based (C,), -1 for
    the corners of a polygon without uvs; an index 0 or out of range names its line."""
    vertex = what == "vertex"
    raw = [p.vertices if vertex else p.uvs or [0] * len(p.vertices) for p in polygons]
    flat = np.fromiter(itertools.chain.from_iterable(raw), dtype=np.int64, count=int(starts[-1]))
    sizes = np.diff(starts)
    count = np.repeat(np.array([p.vertex_count if vertex else p.uv_count for p in polygons], dtype=np.int64), sizes)
    has = np.repeat(np.array([vertex or p.uvs is not None for p in polygons], dtype=bool), sizes)
    index = np.where(flat > 0, flat - 1, count + flat)
    bad = has & ((flat == 0) | (index < 0) | (index >= count))
    if bad.any():
        k = int(np.argmax(bad))
        p = polygons[int(np.searchsorted(starts, k, side="right")) - 1]
        problem = (f"{what} index 0 (OBJ indices start at 1)" if flat[k] == 0
                   else f"{what} index {flat[k]} out of range (only {count[k]} defined so far)")
        raise FaceFileError(f"{path}:{p.lineno}: {problem}: {p.line.strip()[:80]!r}")
    return np.where(has, index, -1)


def _split(flat: np.ndarray, starts: np.ndarray) -> list[list[int]]:
    """``flat`` cut at ``starts`` into lists."""
    values = flat.tolist()
    return [values[a:b] for a, b in zip(starts[:-1].tolist(), starts[1:].tolist())]


# -- other formats through trimesh ---------------------------------------------------------------

def _check_bytes(path: Path) -> None:
    """Refuse a file above ``MAX_BYTES`` before it is read."""
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise FaceFileError(f"face mesh {str(path)!r}: {size:,} bytes; files of up to {MAX_BYTES:,} are read")


def _check_vertices(path: Path, count: int) -> None:
    """Refuse a mesh above ``MAX_VERTICES`` (as glTF is: a million is past anything the rig can rig
    in useful time), before its lines are parsed (an OBJ's ``v`` lines counted first)."""
    if count > MAX_VERTICES:
        raise FaceFileError(f"face mesh {str(path)!r}: {count:,} vertices; faces of up to {MAX_VERTICES:,} are read "
                            "(decimate it first)")


def _read_with_trimesh(path: Path):
    import trimesh

    _check_bytes(path)
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
    _check_vertices(path, sum(len(m.vertices) for m in meshes))
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
