"""Reading glTF 2.0 (``.gltf``, ``.glb``) and VRM (a GLB with the VRM extension) as the artist made
it: every mesh primitive apart, placed by its node, with its material's base colour and texture,
its morph targets by name, and a VRM's expressions.

Why our own reader: trimesh drops morph targets and merges what we need kept apart; the format is
small enough that numpy reads it directly. What is read:

* the GLB container (header, JSON chunk, BIN chunk) or a ``.gltf`` JSON with its buffers embedded
  as ``data:`` URIs or as files beside it;
* accessors of every component type, strided or packed, ``normalized`` integers, and ``sparse``
  ones (with or without a base buffer view);
* the default scene's node tree: ``matrix`` or translation / rotation / scale, multiplied down the
  tree; a node that mirrors (negative determinant) has its triangles' winding turned back;
* triangle primitives (``mode`` 4, and strips and fans turned into triangles); points and lines
  are left out;
* ``TEXCOORD_0``, ``COLOR_0``, the material's ``baseColorFactor`` and ``baseColorTexture``
  (the image in a buffer view, a ``data:`` URI or a file beside the glTF), whose factor is
  multiplied into the texture here (in linear light, as glTF means it);
* morph targets' POSITION displacements, named by ``mesh.extras.targetNames`` (Blender's and most
  exporters' convention), else ``target_K``;
* VRM expressions: VRM 0.x ``extensions.VRM.blendShapeMaster.blendShapeGroups`` (binds by mesh,
  weight 0-100) and VRM 1.0 ``extensions.VRMC_vrm.expressions`` (binds by node, weight 0-1), as
  name -> [(mesh, target, weight 0-1)].

Frames: glTF's front faces +z with +y up, which is the face frame (+x the face's own left). A
VRM 0.x model faces -z by that format's rule, so it is turned half a turn about y here.
Any other extension is ignored, unless the file says it cannot be read without it
(``extensionsRequired``: compressed geometry or textures): then it is refused, naming it
(``IGNORABLE`` are required ones read or harmless here). Bad input is one :class:`FaceFileError`
naming the file.
Above ``MAX_VERTICES`` vertices the file is refused before its arrays are read (the rig works on
faces of tens of thousands of vertices; a million is past anything it can rig in useful time), and
a file above ``MAX_BYTES`` before it is read at all.
"""

from __future__ import annotations

import base64
import io
import json
import os
import struct
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from puppet.face.model import FaceFileError

GLB_MAGIC = b"glTF"
CHUNK_JSON, CHUNK_BIN = 0x4E4F534A, 0x004E4942
MAX_VERTICES = 1_000_000
MAX_BYTES = 1 << 30  # a file larger than this is refused before it is read (1 GiB)
COMPONENTS = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
NORMALIZED_SCALE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
IGNORABLE = {"KHR_mesh_quantization", "KHR_materials_unlit", "KHR_materials_emissive_strength"}
"""Extensions a file may require that are read here (quantized accessors: any component type) or
change nothing the rig or the renderer use."""
COMPRESSED = {"KHR_draco_mesh_compression": "Draco-compressed geometry", "EXT_meshopt_compression":
              "meshopt-compressed buffers", "KHR_texture_basisu": "Basis Universal (KTX2) textures",
              "EXT_texture_webp": "WebP textures", "EXT_texture_avif": "AVIF textures"}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN = 4, 5, 6


@dataclass
class GltfPiece:
    """One triangle primitive of the scene, placed in the scene's frame."""

    mesh: int  # index of its glTF mesh
    names: tuple[str, str, str]  # (mesh name, node name, material name), "" where unnamed
    positions: np.ndarray  # (n, 3) float64
    triangles: np.ndarray  # (f, 3) int64, indices into positions
    uv: np.ndarray | None  # (n, 2) float64 TEXCOORD_0, glTF's convention (v down the image)
    colors: np.ndarray | None  # (n, 3) float32 sRGB albedo: base colour factor x COLOR_0; None: no material
    texture: np.ndarray | None  # (H, W, 3) uint8 sRGB base colour texture, factor multiplied in
    targets: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (n, 3) displacement


@dataclass
class GltfScene:
    """A glTF file's triangle primitives in scene order and its VRM expressions."""

    pieces: list[GltfPiece]
    expressions: dict[str, list[tuple[int, int, float]]]  # name -> [(mesh, target index, weight 0-1)]
    target_names: dict[int, list[str]]  # mesh -> its morph targets' names in order
    extensions: list[str]  # extensionsUsed, as the file says


def read_gltf(path: str | os.PathLike) -> GltfScene:
    """The glTF / GLB / VRM file at ``path`` (module docstring)."""
    reader = _Reader(Path(path))
    try:
        return reader.scene()
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        if isinstance(exc, FaceFileError):
            raise
        raise reader.fail(f"malformed glTF ({type(exc).__name__}: {exc})") from None


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Linear light 0-1 to sRGB 0-1 (IEC 61966-2-1)."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def srgb_decode(srgb: np.ndarray) -> np.ndarray:
    """sRGB 0-1 to linear light 0-1."""
    x = np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


class _Reader:
    """One file's JSON, buffers and images, read as asked for and kept."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.doc, self.bin = self._container()
        self.buffers: dict[int, bytes] = {}
        self.textures: dict[tuple, np.ndarray | None] = {}

    def fail(self, what: str) -> FaceFileError:
        return FaceFileError(f"face mesh {str(self.path)!r}: {what}")

    # -- container ------------------------------------------------------------------------------

    def _container(self) -> tuple[dict, bytes | None]:
        try:
            size = self.path.stat().st_size
            if size > MAX_BYTES:
                raise self.fail(f"{size:,} bytes; files of up to {MAX_BYTES:,} are read")
            data = self.path.read_bytes()
        except OSError as exc:
            raise self.fail(f"cannot read it ({exc.strerror or exc})") from None
        if data[:4] == GLB_MAGIC:
            text, blob = self._glb_chunks(data)
        elif self.path.suffix.lower() in (".glb", ".vrm"):
            raise self.fail("not a binary glTF (it does not start with 'glTF')")
        else:
            text, blob = data, None
        try:
            doc = json.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
            raise self.fail(f"its glTF JSON does not parse ({exc})") from None
        if not isinstance(doc, dict) or not str(doc.get("asset", {}).get("version", "")).startswith("2"):
            raise self.fail("not glTF 2.0 (asset.version is not 2.x)")
        return doc, blob

    def _glb_chunks(self, data: bytes) -> tuple[bytes, bytes | None]:
        if len(data) < 20:
            raise self.fail(f"truncated GLB ({len(data)} bytes, not even a header and a chunk)")
        _, version, length = struct.unpack_from("<III", data, 0)
        if version != 2:
            raise self.fail(f"GLB version {version}, expected 2")
        if length > len(data):
            raise self.fail(f"truncated GLB: its header says {length} bytes, the file has {len(data)}")
        chunks, at = [], 12
        while at + 8 <= length:
            size, kind = struct.unpack_from("<II", data, at)
            if at + 8 + size > length:
                raise self.fail(f"truncated GLB: a chunk of {size} bytes runs past the file's end")
            chunks.append((kind, data[at + 8:at + 8 + size]))
            at += 8 + size + (-size % 4)
        if not chunks or chunks[0][0] != CHUNK_JSON:
            raise self.fail("GLB without a JSON chunk first")
        blob = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == CHUNK_BIN else None
        return chunks[0][1], blob

    def _list(self, key: str) -> list:
        value = self.doc.get(key, [])
        if not isinstance(value, list):
            raise self.fail(f"'{key}' is not a list")
        return value

    def _item(self, key: str, index) -> dict:
        items = self._list(key)
        if not isinstance(index, int) or not 0 <= index < len(items) or not isinstance(items[index], dict):
            raise self.fail(f"{key}[{index}] does not exist")
        return items[index]

    def _uri_bytes(self, uri: str, what: str) -> bytes:
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            try:
                return base64.b64decode(payload, validate=False) if head.endswith(";base64") else \
                    urllib.parse.unquote_to_bytes(payload)
            except ValueError as exc:
                raise self.fail(f"{what}'s data URI does not decode ({exc})") from None
        file = self.path.parent / urllib.parse.unquote(uri)
        try:
            return file.read_bytes()
        except OSError as exc:
            raise self.fail(f"{what}'s file {uri!r} cannot be read beside it ({exc.strerror or exc})") from None

    def _buffer(self, index: int) -> bytes:
        if index not in self.buffers:
            buffer = self._item("buffers", index)
            if "uri" in buffer:
                data = self._uri_bytes(str(buffer["uri"]), f"buffers[{index}]")
            elif index == 0 and self.bin is not None:
                data = self.bin
            else:
                raise self.fail(f"buffers[{index}] has no uri and there is no GLB binary chunk")
            if len(data) < int(buffer.get("byteLength", 0)):
                raise self.fail(f"buffers[{index}] holds {len(data)} bytes, byteLength says {buffer['byteLength']}")
            self.buffers[index] = data
        return self.buffers[index]

    def _view(self, index: int) -> tuple[bytes, int, int, int | None]:
        view = self._item("bufferViews", index)
        data = self._buffer(view.get("buffer", 0))
        offset, length = int(view.get("byteOffset", 0)), int(view.get("byteLength", -1))
        if offset < 0 or length < 0 or offset + length > len(data):
            raise self.fail(f"bufferViews[{index}] reaches past its buffer")
        return data, offset, length, view.get("byteStride")

    # -- accessors ------------------------------------------------------------------------------

    def accessor(self, index: int) -> np.ndarray:
        """(count, width) array of accessor ``index``: float64 for floats and normalized
        integers, int64 for the rest."""
        acc = self._item("accessors", index)
        kind, ctype = acc.get("type"), acc.get("componentType")
        if kind not in WIDTHS or ctype not in COMPONENTS:
            raise self.fail(f"accessors[{index}] has type {kind!r} / componentType {ctype!r}, which glTF has not")
        count, width, dtype = int(acc.get("count", 0)), WIDTHS[kind], np.dtype(COMPONENTS[ctype])
        if "bufferView" in acc:
            out = self._strided(acc["bufferView"], int(acc.get("byteOffset", 0)), count, width, dtype, index)
        else:
            out = np.zeros((count, width), dtype=dtype)
        if "sparse" in acc:
            out = self._sparse(acc["sparse"], out, width, dtype, index)
        if acc.get("normalized") and ctype in NORMALIZED_SCALE:
            return np.maximum(out / NORMALIZED_SCALE[ctype], -1.0)
        return out.astype(np.float64 if ctype == 5126 else np.int64)

    def _strided(self, view_index: int, offset: int, count: int, width: int, dtype: np.dtype,
                 index: int) -> np.ndarray:
        data, start, length, stride = self._view(view_index)
        element = width * dtype.itemsize
        stride = int(stride or element)
        if count and offset + (count - 1) * stride + element > length:
            raise self.fail(f"accessors[{index}] reaches past its buffer view")
        if count == 0:
            return np.zeros((0, width), dtype=dtype)
        return np.ndarray((count, width), dtype=dtype, buffer=data, offset=start + offset,
                          strides=(stride, dtype.itemsize)).copy()

    def _sparse(self, sparse: dict, out: np.ndarray, width: int, dtype: np.dtype, index: int) -> np.ndarray:
        n = int(sparse.get("count", 0))
        idx, values = sparse.get("indices", {}), sparse.get("values", {})
        itype = idx.get("componentType")
        if itype not in (5121, 5123, 5125):
            raise self.fail(f"accessors[{index}].sparse.indices has componentType {itype!r}")
        where = self._strided(idx["bufferView"], int(idx.get("byteOffset", 0)), n, 1, np.dtype(COMPONENTS[itype]),
                              index)[:, 0].astype(np.int64)
        if n and where.max() >= len(out):
            raise self.fail(f"accessors[{index}].sparse points past its {len(out)} elements")
        out = out.copy()
        out[where] = self._strided(values["bufferView"], int(values.get("byteOffset", 0)), n, width, dtype, index)
        return out

    # -- scene ----------------------------------------------------------------------------------

    def scene(self) -> GltfScene:
        self._check_required()
        placed = list(self._placed_meshes())
        self._check_size(placed)
        pieces = [piece for node, mesh_index, matrix in placed
                  for piece in self._pieces(node, mesh_index, matrix)]
        names = {i: _target_names(mesh) for i, mesh in enumerate(self._list("meshes")) if isinstance(mesh, dict)}
        return GltfScene(pieces=pieces, expressions=self._expressions(), target_names=names,
                         extensions=[str(e) for e in self._list("extensionsUsed")])

    def _placed_meshes(self):
        """(node, mesh index, world matrix) for every node with a mesh, depth first in scene order."""
        nodes = self._list("nodes")
        scenes = self._list("scenes")
        if scenes:
            roots = self._item("scenes", self.doc.get("scene", 0)).get("nodes", [])
        else:
            children = {c for n in nodes if isinstance(n, dict) for c in n.get("children", [])}
            roots = [i for i in range(len(nodes)) if i not in children]
        root = self._vrm0_turn()
        stack = [(i, root, ()) for i in reversed(roots)]
        while stack:
            i, parent, path = stack.pop()
            if i in path:
                raise self.fail(f"nodes[{i}] is its own ancestor (a cycle in the node tree)")
            node = self._item("nodes", i)
            world = parent @ self._local(node, i)
            if "mesh" in node:
                yield node, node["mesh"], world
            stack += [(c, world, path + (i,)) for c in reversed(node.get("children", []))]

    def _vrm0_turn(self) -> np.ndarray:
        turn = np.eye(4)
        if isinstance(self.doc.get("extensions", {}).get("VRM"), dict):
            turn[0, 0] = turn[2, 2] = -1.0  # VRM 0.x faces -z
        return turn

    def _local(self, node: dict, i: int) -> np.ndarray:
        try:
            if "matrix" in node:
                return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
            m = np.eye(4)
            x, y, z, w = (float(c) for c in node.get("rotation", (0, 0, 0, 1)))
            m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
            m[:3, :3] *= np.array(node.get("scale", (1, 1, 1)), dtype=np.float64)
            m[:3, 3] = np.array(node.get("translation", (0, 0, 0)), dtype=np.float64)
            return m
        except (TypeError, ValueError) as exc:
            raise self.fail(f"nodes[{i}] has a transform that is not numbers ({exc})") from None

    def _check_required(self) -> None:
        """Refuse a file that needs an extension not read here (``extensionsRequired``), naming it."""
        needed = [str(e) for e in self._list("extensionsRequired") if str(e) not in IGNORABLE]
        if needed:
            what = "; ".join(f"{e} ({COMPRESSED[e]})" if e in COMPRESSED else e for e in needed)
            raise self.fail(f"needs glTF extension(s) {what}, which puppet cannot read: export it again "
                            "without compression, with PNG or JPEG textures")

    def _check_size(self, placed: list) -> None:
        total = 0
        for _, mesh_index, _ in placed:
            for prim in self._item("meshes", mesh_index).get("primitives", []):
                position = prim.get("attributes", {}).get("POSITION")
                if isinstance(position, int):
                    total += int(self._item("accessors", position).get("count", 0))
        if total > MAX_VERTICES:
            raise self.fail(f"{total:,} vertices; faces of up to {MAX_VERTICES:,} are read "
                            "(decimate it first, e.g. Blender's Decimate modifier)")

    def _pieces(self, node: dict, mesh_index: int, world: np.ndarray) -> list[GltfPiece]:
        mesh = self._item("meshes", mesh_index)
        names = _target_names(mesh)
        out = []
        for k, prim in enumerate(mesh.get("primitives", [])):
            where = f"meshes[{mesh_index}].primitives[{k}]"
            attributes = prim.get("attributes", {})
            if prim.get("mode", TRIANGLES) not in (TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN):
                continue
            if "POSITION" not in attributes:
                raise self.fail(f"{where} has no POSITION")
            local = self.accessor(attributes["POSITION"])[:, :3]
            n = len(local)
            triangles = self._triangles(prim, n, where)
            if np.linalg.det(world[:3, :3]) < 0:
                triangles = triangles[:, ::-1]
            material = self._item("materials", prim["material"]) if "material" in prim else None
            out.append(GltfPiece(
                mesh=mesh_index,
                names=(str(mesh.get("name", "")), str(node.get("name", "")),
                       str(material.get("name", "")) if material else ""),
                positions=local @ world[:3, :3].T + world[:3, 3],
                triangles=triangles,
                uv=self._attribute(attributes, "TEXCOORD_0", n, where, 2),
                colors=self._colors(attributes, material, n, where),
                texture=self._texture(material),
                targets={names[t] if t < len(names) else f"target_{t}":
                         self._attribute(target, "POSITION", n, f"{where}.targets[{t}]", 3) @ world[:3, :3].T
                         for t, target in enumerate(prim.get("targets", [])) if "POSITION" in target},
            ))
        return out

    def _attribute(self, attributes: dict, name: str, n: int, where: str, width: int) -> np.ndarray | None:
        if name not in attributes:
            return None
        values = self.accessor(attributes[name])
        if len(values) != n or values.shape[1] < width:
            raise self.fail(f"{where}: {name} has {len(values)} elements of {values.shape[1]}, "
                            f"expected {n} of {width}")
        return values[:, :width].astype(np.float64)

    def _triangles(self, prim: dict, n: int, where: str) -> np.ndarray:
        index = self.accessor(prim["indices"])[:, 0] if "indices" in prim else np.arange(n)
        if len(index) and (index.min() < 0 or index.max() >= n):
            raise self.fail(f"{where}: an index points past its {n} vertices")
        mode = prim.get("mode", TRIANGLES)
        if mode == TRIANGLES:
            return index[:len(index) // 3 * 3].reshape(-1, 3).astype(np.int64)
        k = np.arange(max(len(index) - 2, 0))
        if mode == TRIANGLE_STRIP:  # every other triangle turned back so all wind alike
            odd = k % 2 == 1
            return np.stack([index[k], np.where(odd, index[k + 2], index[k + 1]),
                             np.where(odd, index[k + 1], index[k + 2])], axis=1).astype(np.int64)
        return np.stack([np.full(len(k), index[0]), index[k + 1], index[k + 2]], axis=1).astype(np.int64)

    def _colors(self, attributes: dict, material: dict | None, n: int, where: str) -> np.ndarray | None:
        vertex = self._attribute(attributes, "COLOR_0", n, where, 3)
        if material is None and vertex is None:
            return None
        factor = _base_factor(material)
        linear = np.broadcast_to(factor, (n, 3)) * (vertex if vertex is not None else 1.0)
        return srgb_encode(linear).astype(np.float32)

    def _texture(self, material: dict | None) -> np.ndarray | None:
        info = ((material or {}).get("pbrMetallicRoughness") or {}).get("baseColorTexture")
        if not isinstance(info, dict) or "index" not in info:
            return None
        source = self._item("textures", info["index"]).get("source")
        if source is None:
            return None
        factor = _base_factor(material)
        key = (source, *factor.tolist())
        if key not in self.textures:
            srgb = self._image(source)
            if not np.allclose(factor, 1.0):
                srgb = np.round(255 * srgb_encode(srgb_decode(srgb / 255.0) * factor)).astype(np.uint8)
            self.textures[key] = srgb
        return self.textures[key]

    def _image(self, index: int) -> np.ndarray:
        image = self._item("images", index)
        if "bufferView" in image:
            data, offset, length, _ = self._view(image["bufferView"])
            raw = data[offset:offset + length]
        elif "uri" in image:
            raw = self._uri_bytes(str(image["uri"]), f"images[{index}]")
        else:
            raise self.fail(f"images[{index}] has neither a bufferView nor a uri")
        try:
            with Image.open(io.BytesIO(raw)) as picture:
                return np.asarray(picture.convert("RGB"), dtype=np.uint8)
        except (UnidentifiedImageError, OSError, ValueError) as exc:
            raise self.fail(f"images[{index}] is not an image Pillow can read ({exc})") from None

    # -- VRM ------------------------------------------------------------------------------------

    def _expressions(self) -> dict[str, list[tuple[int, int, float]]]:
        extensions = self.doc.get("extensions", {})
        out: dict[str, list[tuple[int, int, float]]] = {}
        vrm0 = extensions.get("VRM") if isinstance(extensions, dict) else None
        if isinstance(vrm0, dict):
            for group in (vrm0.get("blendShapeMaster") or {}).get("blendShapeGroups", []):
                name = group.get("name") or group.get("presetName")
                binds = [(int(b["mesh"]), int(b["index"]), float(b.get("weight", 100)) / 100.0)
                         for b in group.get("binds", []) if "mesh" in b and "index" in b]
                if name:
                    out[str(name)] = binds
        vrm1 = extensions.get("VRMC_vrm") if isinstance(extensions, dict) else None
        if isinstance(vrm1, dict):
            nodes = self._list("nodes")
            for kind in ("preset", "custom"):
                for name, expression in ((vrm1.get("expressions") or {}).get(kind) or {}).items():
                    out[str(name)] = [(int(nodes[b["node"]]["mesh"]), int(b["index"]), float(b.get("weight", 1.0)))
                                      for b in expression.get("morphTargetBinds", [])
                                      if 0 <= b.get("node", -1) < len(nodes) and "mesh" in nodes[b["node"]]]
        return out


def _target_names(mesh: dict) -> list[str]:
    names = (mesh.get("extras") or {}).get("targetNames") if isinstance(mesh.get("extras"), dict) else None
    if not isinstance(names, list):
        prims = mesh.get("primitives") or [{}]
        extras = prims[0].get("extras") if isinstance(prims[0], dict) else None
        names = extras.get("targetNames") if isinstance(extras, dict) else None
    return [str(n) for n in names] if isinstance(names, list) else []


def _base_factor(material: dict | None) -> np.ndarray:
    """The material's linear base colour factor (rgb), glTF's default white without one."""
    factor = ((material or {}).get("pbrMetallicRoughness") or {}).get("baseColorFactor", (1, 1, 1, 1))
    return np.array(factor[:3], dtype=np.float64)
