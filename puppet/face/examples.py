"""Example shapes: artist-made expressions of a face's source mesh, as displacements of the face.

MakeHuman ships expressions of its base mesh as ``.target`` files (text, one line per moved
vertex: ``INDEX DX DY DZ``, INDEX the 0-based base-mesh vertex, DX DY DZ its displacement at full
strength in the base mesh's units and frame). A face cut from that mesh keeps each vertex's base
index in ``Face.source_index`` (-1 for generated vertices: eyeballs, teeth, tongue), so a target
applies to it directly: ``load_examples`` returns one (N, 3) displacement per file, zero where the
target moves nothing or the vertex is generated. The default face is in the base mesh's own frame
and units (``puppet/data/PROVENANCE.md``), so no transform is needed.

``../shared/assets/makehuman/faceunits_arkit/`` holds 52 such targets named after ARKit's
blendshapes; ``puppet.runtime.fapcalibration`` calibrates the rig's FAPs from them and measures the fit.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from puppet.errors import PuppetError


class ExampleError(PuppetError, ValueError):
    """A target file or folder that cannot be applied to a face; the message names file and line."""


def load_examples(face, folder: str | os.PathLike) -> dict[str, np.ndarray]:
    """{target name: (N, 3) displacement of the face's vertices} for every ``*.target`` in
    ``folder``, sorted by name."""
    folder = Path(folder)
    files = sorted(folder.glob("*.target"))
    if not files:
        raise ExampleError(f"{folder}: no .target files")
    if face.source_index is None:
        raise ExampleError(f"face {face.name!r} keeps no source vertex indices: targets cannot apply to it")
    source = np.asarray(face.source_index, dtype=np.int64)
    lookup = np.full(int(source.max(initial=-1)) + 1, -1, dtype=np.int64)
    kept = np.flatnonzero(source >= 0)
    lookup[source[kept]] = kept
    return {path.stem: _displacement(path, lookup, len(face.vertices)) for path in files}


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
