"""An OBJ file's numbers parsed in bulk: every ``v`` line's coordinates in one numpy call, every
``f`` line's indices in another, rather than number by number.

``meshfile.read_obj`` tries this first: a large mesh (the ICT head's 26,719 vertices, the 52
ARKit shapes of the default face) reads several times faster. It reads the plain files that
exporters write: ``v`` lines all with three numbers (or all with six: colours), ``vt`` lines
all with two (or all with three), every corner written alike (``v``, ``v/vt``, ``v//vn`` or
``v/vt/vn``), indices positive and defined before the line. Anything else, a mistake included,
gives None, and the line-by-line reader reads the file and names the line that is wrong. What
both read from a file is the same (``tests/test_face.py``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

NUMBERS_PER_CORNER = {0: 1, 1: 2, 2: 3}
"""Slashes per corner -> the numbers it carries (``v``, ``v/vt``, ``v/vt/vn``; ``v//vn`` has 2)."""


@dataclass
class BulkObj:
    """What ``meshfile.ObjMesh`` is made of, as ``read_bulk`` found it (colours as written)."""

    positions: np.ndarray
    colors: np.ndarray | None
    uvs: np.ndarray
    corners: np.ndarray
    corner_uvs: np.ndarray
    starts: np.ndarray
    groups: list[str | None]
    materials: list[str | None]
    mtllibs: list[str]


LINE = re.compile(r"^[^\S\n]*(vt|v|f|g|usemtl|mtllib)(?!\S)(.*)$", re.MULTILINE)
"""A line the reader keeps: its tag, then the rest (whitespace within a line as ``str.split`` sees it)."""
BREAKS = "\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
"""Line breaks ``str.splitlines`` knows besides \\n and \\r\\n (and a lone \\r): a file with
them is read line by line."""


class _Lines:
    """An OBJ's lines sorted by tag, as the line-by-line reader sorts them: the text after the tag
    of each ``v``, ``vt`` and ``f`` line; for each ``f`` line its group, material and how many
    vertices and uvs were defined before it; the ``mtllib`` names. Other tags are skipped.
    ``plain`` is False where the file breaks lines in ways a regular expression does not."""

    def __init__(self, text: str) -> None:
        self.plain = not any(mark in text for mark in BREAKS) and text.count("\r") == text.count("\r\n")
        lines = LINE.findall(text)
        tags = np.array([tag for tag, _ in lines])
        by_tag: dict[str, list[str]] = {tag: [] for tag in ("v", "vt", "f", "g", "usemtl", "mtllib")}
        for tag, rest in lines:
            by_tag[tag].append(rest)
        self.v, self.vt, self.f = by_tag["v"], by_tag["vt"], by_tag["f"]
        g, usemtl, mtllib = by_tag["g"], by_tag["usemtl"], by_tag["mtllib"]
        is_f = tags == "f"
        self.defined = np.stack([np.cumsum(tags == "v")[is_f], np.cumsum(tags == "vt")[is_f]], axis=1)
        self.groups = _named(g, np.cumsum(tags == "g")[is_f])
        self.materials = _named(usemtl, np.cumsum(tags == "usemtl")[is_f])
        self.mtllibs = [" ".join(rest.split()) for rest in mtllib]


def _named(lines: list[str], count: np.ndarray) -> list[str | None]:
    """For each ``f`` line, the name the last of ``lines`` (``g`` or ``usemtl``) before it gives:
    ``count`` of them came before it; None before the first, or where the line names nothing."""
    names = [None] + [" ".join(rest.split()) or None for rest in lines]
    return [names[k] for k in count.tolist()]


def read_bulk(text: str) -> BulkObj | None:
    """The OBJ ``text`` read in bulk, or None where it is not plain (module docstring)."""
    lines = _Lines(text)
    if not lines.plain:
        return None
    positions = _numbers(lines.v, (3, 6))
    uvs = _numbers(lines.vt, (2, 3))
    if positions is None or uvs is None or not len(positions):
        return None
    polygons = _corners(lines)
    if polygons is None:
        return None
    corners, corner_uvs, starts = polygons
    return BulkObj(positions=np.ascontiguousarray(positions[:, :3]),
                   colors=positions[:, 3:6].astype(np.float32) if positions.shape[1] == 6 else None,
                   uvs=np.ascontiguousarray(uvs[:, :2]).reshape(-1, 2), corners=corners, corner_uvs=corner_uvs,
                   starts=starts, groups=lines.groups, materials=lines.materials, mtllibs=lines.mtllibs)


def _numbers(lines: list[str], widths: tuple[int, ...]) -> np.ndarray | None:
    """The numbers of ``lines`` as (len(lines), k), where every line holds k numbers and k is one of
    ``widths``; else None."""
    counts = {len(line.split()) for line in lines}
    if not lines:
        return np.zeros((0, widths[0]))
    if len(counts) != 1 or (width := counts.pop()) not in widths:
        return None
    try:
        flat = np.array(" ".join(lines).split(), dtype=np.float64)
    except ValueError:
        return None
    return flat.reshape(len(lines), width)


def _corners(lines: _Lines) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(vertex index of each corner (C,), uv index (C,) or -1 where none, polygon starts (P + 1,)),
    0-based, where every ``f`` line has 3 or more corners written alike and every index is positive
    and defined before its line; else None."""
    split = [line.split() for line in lines.f]
    sizes = np.fromiter((len(c) for c in split), dtype=np.int64, count=len(split))
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    total = int(starts[-1])
    if not total:
        return (np.zeros(0, dtype=np.int64),) * 2 + (starts,) if not len(sizes) else None
    if sizes.min() < 3:
        return None
    every = np.array([corner for corners in split for corner in corners])
    slashes, doubled = np.unique(np.char.count(every, "/")), np.unique(np.char.count(every, "//"))
    if len(slashes) != 1 or slashes[0] not in NUMBERS_PER_CORNER or len(doubled) != 1:
        return None
    per = NUMBERS_PER_CORNER[int(slashes[0])] - int(doubled[0])
    try:
        flat = np.array(" ".join(every.tolist()).replace("/", " ").split(), dtype=np.int64)
    except ValueError:
        return None
    if len(flat) != per * total:
        return None
    table = flat.reshape(total, per)
    defined = np.repeat(lines.defined.reshape(-1, 2), sizes, axis=0)
    vertices = table[:, 0] - 1
    if vertices.min() < 0 or (vertices >= defined[:, 0]).any():
        return None
    if per == 1 or doubled[0]:
        return vertices, np.full(total, -1, dtype=np.int64), starts
    uvs = table[:, 1] - 1
    if uvs.min() < 0 or (uvs >= defined[:, 1]).any():
        return None
    return vertices, uvs, starts
