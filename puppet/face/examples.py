"""Example shapes: artist-made expressions of a face's source mesh, as displacements of the face.

MakeHuman ships expressions of its base mesh as ``.target`` files (text, one line per moved
vertex: ``INDEX DX DY DZ``, INDEX the 0-based base-mesh vertex, DX DY DZ its displacement at full
strength in the base mesh's units and frame). A face cut from that mesh keeps each vertex's base
index in ``Face.source_index`` (-1 for generated vertices: eyeballs, teeth, tongue), so a target
applies to it directly: ``load_examples`` returns one (N, 3) displacement per file, zero where the
target moves nothing or the vertex is generated. The default face is in the base mesh's own frame
and units (``puppet/data/PROVENANCE.md``), so no transform is needed.

A studio's shapes of any other face come as meshes: an ``.obj`` with the face's own vertices in
the face's order and units, in a new shape (a blendshape exported from the mesh the face was
rigged from); its displacement is its vertices less the face's rest ones. A folder may hold both
kinds; each name (the file's stem) once.

A glTF / GLB / VRM file of the face (the one it was rigged from) holds its shapes as morph
targets: ``load_examples(face, "head.glb")`` reads each as a named shape (``mesh.extras.targetNames``,
the vertices of all its meshes in the face's order), and a VRM's expressions as the weighted sums of
the targets they bind. A name that is one of ARKit's 52 blendshapes in any case or after a prefix
(``BrowDownLeft``, ``blendShape1.browDownLeft``: VTuber "perfect sync" models) is spelt as ARKit
spells it (``ARKIT_NAMES``), so such a file's shapes are ARKit shapes like MakeHuman's. A face
turned into the face frame by its landmarks (``Face.placement``) has the shapes turned with it.

``../shared/assets/makehuman/faceunits_arkit/`` holds 52 such targets named after ARKit's
blendshapes; ``puppet.runtime.fapcalibration`` calibrates the rig's FAPs from them and measures the
fit, and ``puppet calibrate-face`` does it for any face folder.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from puppet.errors import PuppetError
from puppet.face.gltfread import read_gltf
from puppet.face.meshfile import GLTF_SUFFIXES, read_obj

ARKIT_NAMES = (
    "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight", "cheekPuff",
    "cheekSquintLeft", "cheekSquintRight", "eyeBlinkLeft", "eyeBlinkRight", "eyeLookDownLeft", "eyeLookDownRight",
    "eyeLookInLeft", "eyeLookInRight", "eyeLookOutLeft", "eyeLookOutRight", "eyeLookUpLeft", "eyeLookUpRight",
    "eyeSquintLeft", "eyeSquintRight", "eyeWideLeft", "eyeWideRight", "jawForward", "jawLeft", "jawOpen", "jawRight",
    "mouthClose", "mouthDimpleLeft", "mouthDimpleRight", "mouthFrownLeft", "mouthFrownRight", "mouthFunnel",
    "mouthLeft", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthPressLeft", "mouthPressRight", "mouthPucker",
    "mouthRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper", "mouthSmileLeft",
    "mouthSmileRight", "mouthStretchLeft", "mouthStretchRight", "mouthUpperUpLeft", "mouthUpperUpRight",
    "noseSneerLeft", "noseSneerRight", "tongueOut",
)
_ARKIT_BY_LOWER = {name.lower(): name for name in ARKIT_NAMES}


class ExampleError(PuppetError, ValueError):
    """A target file or folder that cannot be applied to a face; the message names file and line."""


def load_examples(face, folder: str | os.PathLike) -> dict[str, np.ndarray]:
    """{name: (N, 3) displacement of the face's vertices} for every ``*.target`` and ``*.obj`` in
    ``folder``, or every morph target and expression of a glTF / GLB / VRM file, sorted by name
    (module docstring)."""
    folder = Path(folder)
    if folder.is_file() and folder.suffix.lower() in GLTF_SUFFIXES:
        return dict(sorted(gltf_examples(face, folder).items()))
    if not folder.is_dir():
        raise ExampleError(f"{folder}: not a folder of example shapes")
    files = sorted(folder.glob("*.target")) + sorted(folder.glob("*.obj"))
    if not files:
        raise ExampleError(f"{folder}: no example shapes (.target or .obj files)")
    twice = sorted({p.stem for p in files if sum(q.stem == p.stem for q in files) > 1})
    if twice:
        raise ExampleError(f"{folder}: {', '.join(twice)}: one shape per name (found a .target and an .obj)")
    shapes = {path.stem: _shape_mesh(path, face) for path in files if path.suffix == ".obj"}
    targets = [path for path in files if path.suffix == ".target"]
    if targets:
        lookup = _source_lookup(face, targets[0])
        shapes |= {path.stem: _displacement(path, lookup, len(face.vertices)) for path in targets}
    return dict(sorted(shapes.items()))


def gltf_examples(face, path: str | os.PathLike) -> dict[str, np.ndarray]:
    """{name: (N, 3) displacement} of a glTF file's morph targets, then its VRM expressions under
    names not taken; ARKit names spelt as ARKit does (module docstring)."""
    path = Path(path)
    scene = read_gltf(path)
    n = sum(len(p.positions) for p in scene.pieces)
    if n != len(face.vertices):
        raise ExampleError(f"{path}: {n} vertices, but face {face.name!r} has {len(face.vertices)}: its morph "
                           "targets are shapes of the face it was rigged from, vertex for vertex")
    starts = np.cumsum([0] + [len(p.positions) for p in scene.pieces])
    shapes: dict[str, np.ndarray] = {}
    for piece, start in zip(scene.pieces, starts):
        for name, delta in piece.targets.items():
            shapes.setdefault(_spelt(name), np.zeros((n, 3)))[start:start + len(delta)] += delta
    for name, binds in scene.expressions.items():
        if _spelt(name).lower() in {k.lower() for k in shapes} or not binds:
            continue
        total = np.zeros((n, 3))
        for mesh, index, weight in binds:
            for piece, start in zip(scene.pieces, starts):
                names = scene.target_names.get(mesh, [])
                target = names[index] if index < len(names) else f"target_{index}"
                if piece.mesh == mesh and target in piece.targets:
                    total[start:start + len(piece.positions)] += weight * piece.targets[target]
        shapes[_spelt(name)] = total
    if not shapes:
        raise ExampleError(f"{path}: no morph targets (blendshapes) to learn from")
    if face.placement is not None:  # the face was turned into the face frame: turn its shapes alike
        rotation = np.asarray(face.placement, dtype=float)[:, :3]
        shapes = {k: v @ rotation.T for k, v in shapes.items()}
    return shapes


def _spelt(name: str) -> str:
    """ARKit's spelling of an ARKit blendshape name in any case or after a prefix; others as given."""
    return _ARKIT_BY_LOWER.get(name.rsplit(".", 1)[-1].lower(), name)


def _source_lookup(face, first: Path) -> np.ndarray:
    """Face vertex per source-mesh vertex (-1: not on the face), for ``.target`` files."""
    if face.source_index is None:
        raise ExampleError(f"{first}: face {face.name!r} keeps no source vertex indices, so a .target cannot "
                           "apply to it; give its shapes as .obj meshes of the face")
    source = np.asarray(face.source_index, dtype=np.int64)
    lookup = np.full(int(source.max(initial=-1)) + 1, -1, dtype=np.int64)
    kept = np.flatnonzero(source >= 0)
    lookup[source[kept]] = kept
    return lookup


def _shape_mesh(path: Path, face) -> np.ndarray:
    """The displacement an example ``.obj`` (the face's vertices, in a new shape) makes."""
    positions = read_obj(path).positions
    if positions.shape != face.vertices.shape:
        raise ExampleError(f"{path}: {len(positions)} vertices, but face {face.name!r} has {len(face.vertices)}: "
                           "an example mesh is the face's own mesh in a new shape, vertex for vertex")
    return positions - np.asarray(face.vertices, dtype=float)


def _displacement(path: Path, lookup: np.ndarray, n: int) -> np.ndarray:
    rows = read_target(path)
    out = np.zeros((n, 3))
    index = rows[:, 0].astype(np.int64)
    inside = index < len(lookup)
    vertex = np.full(len(index), -1)
    vertex[inside] = lookup[index[inside]]
    on_face = vertex >= 0
    out[vertex[on_face]] = rows[on_face, 1:]
    return out


def read_target(path: str | os.PathLike) -> np.ndarray:
    """A ``.target`` file as rows (index, dx, dy, dz); comment lines (``#``) and blank lines are
    skipped."""
    rows = []
    for lineno, line in enumerate(Path(path).read_text("utf-8").splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        try:
            if len(fields) != 4 or int(fields[0]) < 0:
                raise ValueError
            rows.append((int(fields[0]), float(fields[1]), float(fields[2]), float(fields[3])))
        except ValueError:
            raise ExampleError(f"{path}:{lineno}: expected 'INDEX DX DY DZ', found {line.strip()[:60]!r}") from None
    return np.array(rows, dtype=float).reshape(-1, 4)
