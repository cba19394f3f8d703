"""Exporting a take to glTF 2.0 binary (.glb): the face mesh, animated by morph targets.

glTF cannot animate vertex positions directly; it animates morph-target ``weights``. Two modes:

* ``mode="morph"`` (default): the frames' position displacements from the rest mesh, a
  (frames x 3N) matrix, are compressed by a truncated SVD (uncentred PCA) to ``k`` basis vectors:
  the fewest that explain 99.9% of the displacement energy, then more while some vertex is off by
  more than ``tolerance`` (energy alone leaves visible local errors), at most 32. The basis
  vectors become the morph targets (POSITION deltas) and the per-frame coefficients animate the
  node's weights through a LINEAR sampler at the take's fps. The largest vertex error of the reconstruction
  (float32 as stored, against the played frame) is reported.
* ``mode="frames"``: one morph target per frame (its exact displacement), weights one-hot per
  frame with a STEP sampler. Exact, but the file grows with frames x vertices, so a take longer
  than ``FRAMES_LIMIT`` frames is refused unless ``max_frames`` says how many to export.

Normals are the rest normals (morph targets carry POSITION only). ``max_frames`` exports only the
first ``max_frames`` frames of the take in either mode. The playback (and so the SVD input) is
held in memory as float32: frames x 3N x 4 bytes, so a take longer than ``MORPH_FRAMES_LIMIT``
frames is refused unless ``max_frames`` is given.
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Callable

import numpy as np

from puppet.face.model import Face
from puppet.io.outputs import writable
from puppet.io.takes import TakeError
from puppet.view.rendertake import FapPlayback

GLB_MAGIC, GLB_VERSION = 0x46546C67, 2
CHUNK_JSON, CHUNK_BIN = 0x4E4F534A, 0x004E4942
FLOAT, UINT32 = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
MAX_TARGETS, EXPLAINED = 32, 0.999
FRAMES_LIMIT = 256
MORPH_FRAMES_LIMIT = 18_000  # 10 minutes at 30 fps; about 2.2 GB of float32 frames on the default face
_EXACT_SVD_LIMIT = 1500


def _basis(D: np.ndarray, max_k: int, explained: float,
           tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weights (F, k) and targets (k, C) with D ~= weights @ targets (truncated SVD): the fewest
    targets explaining ``explained`` of the energy, then more (up to ``max_k``) while a vertex
    is further than ``tolerance`` from its frame."""
    total = float(np.einsum("ij,ij->", D, D, dtype=np.float64))
    if total == 0.0:
        return np.zeros((len(D), 0)), np.zeros((0, D.shape[1]))
    if min(D.shape) <= _EXACT_SVD_LIMIT:
        U, s, Vt = np.linalg.svd(D.astype(np.float64), full_matrices=False)
    else:  # randomized range finder with power iterations (Halko et al.)
        rng = np.random.default_rng(0)
        Q = np.linalg.qr(D @ rng.standard_normal((D.shape[1], max_k + 16)).astype(D.dtype))[0]
        for _ in range(3):
            Q = np.linalg.qr(D.T @ Q)[0]
            Q = np.linalg.qr(D @ Q)[0]
        Ub, s, Vt = np.linalg.svd((Q.T @ D).astype(np.float64), full_matrices=False)
        U = Q.astype(np.float64) @ Ub
    share = np.cumsum(s ** 2) / total
    k = min(int(np.searchsorted(share, explained - 1e-12)) + 1, max_k, len(s))
    if tolerance is not None:  # add targets while some vertex is further off than tolerance
        residual = D.astype(np.float32) - (U[:, :k] * s[:k]).astype(np.float32) @ Vt[:k].astype(np.float32)
        while k < min(max_k, len(s)) and _worst(residual) > tolerance:
            residual -= np.outer(U[:, k] * s[k], Vt[k]).astype(np.float32)
            k += 1
    return U[:, :k] * s[:k], Vt[:k]


def _worst(residual: np.ndarray) -> float:
    """The largest per-vertex distance in a (F, 3N) residual."""
    return float(np.sqrt((residual.reshape(len(residual), -1, 3) ** 2).sum(axis=2).max()))


class _Builder:
    """Accumulates the binary chunk and the bufferViews / accessors that describe it."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, array: np.ndarray, type_: str, target: int | None = None, *,
            bounds: bool = False) -> int:
        array = np.ascontiguousarray(array)
        component = UINT32 if array.dtype == np.uint32 else FLOAT
        array = array.astype("<u4" if component == UINT32 else "<f4", copy=False)
        self.blob += b"\0" * (-len(self.blob) % 4)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": array.nbytes}
        if target is not None:
            view["target"] = target
        self.views.append(view)
        self.blob += array.tobytes()
        width = {"SCALAR": 1, "VEC3": 3}[type_]
        flat = array.reshape(-1, width)
        accessor = {"bufferView": len(self.views) - 1, "componentType": component,
                    "count": len(flat), "type": type_}
        if bounds:
            accessor["min"] = [float(x) for x in flat.min(axis=0)]
            accessor["max"] = [float(x) for x in flat.max(axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1


def _unit(normals: np.ndarray) -> np.ndarray:
    n = np.asarray(normals, dtype=np.float64)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 1e-12, n / np.maximum(length, 1e-12), [0.0, 0.0, 1.0])
    return n.astype(np.float32)


def export_glb(take_or_fap_path: str | os.PathLike, out_path: str | os.PathLike, *,
               mode: str = "morph", max_frames: int | None = None,
               face: Face | None = None, tolerance: float | None = None,
               step: Callable[[int, int, str], None] | None = None) -> dict:
    """Export a take (a .fap or a take folder) on the face (default: the default face) to .glb;
    ``step(k, n, what)`` hears each of its ``n`` steps as it starts (``puppet export``'s progress).

    Returns {"frames", "targets", "max_error", "extent", "bytes", "mode", "fps"}; ``max_error`` is
    the largest distance (mesh units) between a played vertex and its glTF reconstruction,
    ``extent`` the rest mesh's largest extent (mesh units), to say it against.
    In morph mode, targets are added beyond the 99.9%-energy count (up to 32) while the error
    exceeds ``tolerance`` (default: 1/1000 of the rest mesh's largest extent).
    """
    if mode not in ("morph", "frames"):
        raise ValueError(f"mode {mode!r}: expected 'morph' or 'frames'")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be at least 1, got {max_frames}")
    out_path = writable(out_path, ".glb")
    step = step or (lambda k, n, what: None)
    playback = FapPlayback(take_or_fap_path, face)
    rest = np.asarray(playback.runtime.rest, dtype=np.float64)
    rest32 = rest.astype(np.float32)
    step(1, 3, "playing the take on the face")
    D = _displacements(playback, take_or_fap_path, rest32, mode, max_frames)
    frames, n = len(D), len(rest)
    step(2, 3, f"the morph targets of {frames} frames" if mode == "morph" else f"a morph target per frame ({frames})")
    if mode == "morph":
        if tolerance is None:
            tolerance = 1e-3 * float(np.ptp(rest, axis=0).max())
        weights, targets = _basis(D, MAX_TARGETS, EXPLAINED, tolerance)
    else:
        weights, targets = np.eye(frames), D
    weights32 = weights.astype(np.float32)
    targets32 = targets.astype(np.float32).reshape(len(targets), n, 3)
    step(3, 3, "every frame played again against its reconstruction, and the file written")
    max_error = _max_error(playback, rest32, weights32, targets32, frames)
    interpolation = "LINEAR" if mode == "morph" else "STEP"
    b = _Builder()
    gltf = _document(b, playback, rest32, weights32, targets32, interpolation)
    total = _write_glb(out_path, gltf, b.blob)
    return {"frames": frames, "targets": len(targets32), "max_error": max_error, "bytes": total,
            "mode": mode, "fps": playback.fps, "extent": float(np.ptp(rest, axis=0).max())}


def _displacements(playback: FapPlayback, source: str | os.PathLike, rest32: np.ndarray, mode: str,
                   max_frames: int | None) -> np.ndarray:
    """Every played frame's displacement from rest, (frames, 3V) float32, within the mode's limits."""
    limit = max_frames if max_frames is not None else (FRAMES_LIMIT if mode == "frames" else MORPH_FRAMES_LIMIT) + 1
    played = []
    for vertices, _normals in playback:
        if len(played) >= limit:
            break
        played.append(np.asarray(vertices, dtype=np.float32))
    if not played:
        raise TakeError(f"{source}: the take holds no frames")
    if mode == "frames" and max_frames is None and len(played) > FRAMES_LIMIT:
        raise TakeError(f"{source}: more than {FRAMES_LIMIT} frames; mode='frames' "
                        "makes one morph target per frame -- pass max_frames or use mode='morph'")
    if max_frames is None and len(played) > MORPH_FRAMES_LIMIT:
        raise TakeError(f"{source}: more than {MORPH_FRAMES_LIMIT} frames, which the export"
                        " holds in memory at once -- pass max_frames (or export it in parts)")
    return (np.stack(played) - rest32).reshape(len(played), -1)


def _document(b: _Builder, playback: FapPlayback, rest32: np.ndarray, weights32: np.ndarray,
              targets32: np.ndarray, interpolation: str) -> dict:
    """The glTF JSON of the face mesh with its morph targets and their animated weights, its
    arrays added to ``b``."""
    face, runtime = playback.face, playback.runtime
    position = b.add(rest32, "VEC3", ARRAY_BUFFER, bounds=True)
    normal = b.add(_unit(runtime.rest_normals), "VEC3", ARRAY_BUFFER)
    attributes = {"POSITION": position, "NORMAL": normal}
    if face.colors is not None:
        attributes["COLOR_0"] = b.add(np.clip(np.asarray(face.colors, dtype=np.float32), 0, 1),
                                      "VEC3", ARRAY_BUFFER)
    indices = b.add(np.asarray(face.triangles, dtype=np.uint32).ravel(), "SCALAR", ELEMENT_ARRAY_BUFFER)
    primitive = {"attributes": attributes, "indices": indices, "material": 0, "mode": 4}
    mesh: dict = {"name": "face", "primitives": [primitive]}
    gltf: dict = {
        "asset": {"version": "2.0", "generator": "puppet.view.gltf"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "face", "mesh": 0}],
        "materials": [{"name": "skin", "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6}}],
        "meshes": [mesh],
    }
    if len(targets32):
        primitive["targets"] = [{"POSITION": b.add(t, "VEC3", ARRAY_BUFFER, bounds=True)} for t in targets32]
        mesh["weights"] = [0.0] * len(targets32)
        times = b.add(np.arange(len(weights32), dtype=np.float32) / np.float32(playback.fps), "SCALAR", bounds=True)
        values = b.add(weights32.ravel(), "SCALAR")
        gltf["animations"] = [{
            "name": "take",
            "samplers": [{"input": times, "output": values, "interpolation": interpolation}],
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
        }]
    b.blob += b"\0" * (-len(b.blob) % 4)
    gltf.update(bufferViews=b.views, accessors=b.accessors, buffers=[{"byteLength": len(b.blob)}])
    return gltf


def _write_glb(out_path: str | os.PathLike, gltf: dict, blob: bytes | bytearray) -> int:
    """Write the binary glTF container (header, JSON chunk, BIN chunk); return its size in bytes."""
    text = json.dumps(gltf, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    with open(out_path, "wb") as out:
        out.write(struct.pack("<III", GLB_MAGIC, GLB_VERSION, total))
        out.write(struct.pack("<II", len(text), CHUNK_JSON) + text)
        out.write(struct.pack("<II", len(blob), CHUNK_BIN) + bytes(blob))
    return total


def _max_error(playback: FapPlayback, rest32: np.ndarray, weights32: np.ndarray,
               targets32: np.ndarray, frames: int) -> float:
    """Largest distance between a played vertex and rest + weights @ targets (float32, as stored)."""
    worst = 0.0
    flat = targets32.reshape(len(targets32), -1)
    for i, (vertices, _normals) in enumerate(playback):
        if i >= frames:
            break
        built = rest32.ravel() + weights32[i] @ flat if len(flat) else rest32.ravel()
        err = np.linalg.norm(built.reshape(-1, 3).astype(np.float64) - vertices, axis=1).max()
        worst = max(worst, float(err))
    return worst


def error_words(max_error: float, extent: float, mm_per_unit: float | None = None) -> str:
    """``export_glb``'s largest vertex error as the terminal says it: in millimetres when the face's
    unit is known (``mm_per_unit``: the default face's), else in the mesh file's own units; and as a
    share of the face's size either way."""
    share = f"{100 * max_error / extent:.2g}% of the face's"
    if mm_per_unit is None:
        return (f"largest vertex error {max_error:.2g} mesh units (the face file's own unit; {share} "
                f"{extent:.3g}-unit size)")
    return f"largest vertex error {max_error * mm_per_unit:.2g} mm ({share} {extent * mm_per_unit:.0f} mm size)"
