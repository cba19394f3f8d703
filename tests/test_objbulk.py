"""An OBJ read in bulk is the OBJ read line by line: the same numbers, polygons, groups and
materials, or no bulk reading at all (and then the line-by-line reader's answer or message)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.face import meshfile
from puppet.face.model import FaceFileError
from puppet.face.objbulk import read_bulk

FIELDS = ("positions", "uvs", "corners", "corner_uvs", "starts")


def same(a: meshfile.ObjMesh, b: meshfile.ObjMesh) -> bool:
    arrays = all(np.array_equal(getattr(a, name), getattr(b, name)) for name in FIELDS)
    colors = (a.colors is None) == (b.colors is None) and (a.colors is None or np.array_equal(a.colors, b.colors))
    return arrays and colors and (a.groups, a.materials, a.mtllibs) == (b.groups, b.materials, b.mtllibs)


def read_both(tmp_path: Path, text: str):
    """(read_obj's answer or message, the line-by-line reader's answer or message)."""
    path = tmp_path / "mesh.obj"
    path.write_text(text, encoding="utf-8", newline="")
    answers = []
    for read in (meshfile.read_obj, lambda p: meshfile._read_lines(p, p.read_text(encoding="utf-8"))):
        try:
            answers.append(read(path))
        except FaceFileError as exc:
            answers.append(str(exc))
    return answers


number = st.floats(-10, 10, allow_nan=False).map(lambda x: f"{x:.6g}")
corner_forms = st.sampled_from(["{v}", "{v}/{t}", "{v}//{v}", "{v}/{t}/{v}"])


@st.composite
def obj_texts(draw) -> str:
    """OBJ texts, mostly plain, some with what the bulk reader leaves to the other: relative or
    out-of-range indices, mixed corner forms, uneven vertex lines, faces before their vertices."""
    n = draw(st.integers(3, 8))
    width = draw(st.sampled_from([3, 6]))
    lines = [f"v {' '.join(draw(number) for _ in range(width))}" for _ in range(n)]
    if draw(st.booleans()):
        lines[draw(st.integers(0, n - 1))] += " 1"
    lines += [f"vt {draw(number)} {draw(number)}" for _ in range(draw(st.integers(0, n)))]
    forms = draw(st.lists(corner_forms, min_size=1, max_size=2))
    for _ in range(draw(st.integers(0, 6))):
        if draw(st.integers(0, 4)) == 0:
            lines.append(draw(st.sampled_from(["g jaw", "g", "usemtl skin ", "mtllib a.mtl", "# note", "vn 0 0 1", "s 1"])))
        corners = []
        for _ in range(draw(st.integers(2, 5))):
            v, t = draw(st.integers(-2, n + 1)), draw(st.integers(1, n))
            corners.append(draw(st.sampled_from(forms)).format(v=v, t=t))
        lines.append("f " + draw(st.sampled_from([" ", "\t", "  "])).join(corners))
    if draw(st.booleans()):
        lines.insert(draw(st.integers(0, len(lines))), f"v {draw(number)} {draw(number)} {draw(number)}")
    return draw(st.sampled_from(["\n", "\r\n"])).join(lines) + "\n"


@settings(max_examples=300, deadline=None)
@given(text=obj_texts())
def test_bulk_reads_what_the_lines_say(tmp_path_factory, text: str) -> None:
    fast, slow = read_both(tmp_path_factory.mktemp("obj"), text)
    if isinstance(slow, str):
        assert fast == slow
    else:
        assert same(fast, slow)


def test_plain_file_is_read_in_bulk_with_groups_materials_and_colours(tmp_path: Path) -> None:
    text = ("mtllib face.mtl\nv 0 0 0 255 0 0\nv 1 0 0 0 255 0\nv 0 1 0 0 0 255\nv 1 1 0 9 9 9\nvt 0 0\nvt 1 0\n"
            "vt 0 1\ng lips\nusemtl red\nf 1/1 2/2 3/3\ng\nf 2/2 4/1 3/3\n")
    bulk = read_bulk(text)
    assert bulk is not None
    fast, slow = read_both(tmp_path, text)
    assert same(fast, slow)
    assert fast.groups == ["lips", None] and fast.materials == ["red", "red"]
    assert fast.colors[0].tolist() == [1.0, 0.0, 0.0]


@pytest.mark.parametrize("text", ["v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -1\n",    # relative index
                                  "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n",     # a face before its vertex
                                  "v 0 0 0\nv 1 0 0\rv 0 1 0\nf 1 2 3\n",     # a lone carriage return
                                  "v 0 0 0\nv 1 0 0 1\nv 0 1 0\nf 1 2 3\n"])  # an uneven vertex line
def test_what_is_not_plain_is_left_to_the_line_reader(tmp_path: Path, text: str) -> None:
    assert read_bulk(text) is None
    fast, slow = read_both(tmp_path, text)
    assert fast == slow if isinstance(slow, str) else same(fast, slow)
