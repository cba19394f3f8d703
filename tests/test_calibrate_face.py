"""``puppet calibrate-face``: a face's FAP motions learnt from example shapes of it (``.obj``
meshes of its vertices, or MakeHuman targets), written as a face folder that loads with its own
calibrated rig, the fit on shapes it never saw reported apart; bad example folders named."""

from __future__ import annotations

import dataclasses
import re
import shutil

import numpy as np
import pytest

from puppet.bench.assets import shared_assets
from puppet.cli import main
from puppet.face.examples import ExampleError, load_examples
from puppet.face.load import load_face
from puppet.runtime.fapcalibration import fit_faps, relative_residual
from puppet.runtime.runtime import Runtime

EXAMPLES = shared_assets() / "makehuman" / "faceunits_arkit"
NOSE = (61, 62, 63, 64)  # stretch_l/r_nose, raise_nose, bend_nose: no smile, jaw or brow moves them


def _write_obj(path, vertices: np.ndarray) -> None:
    path.write_text("\n".join(f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()) + "\n")


def test_an_obj_example_is_its_vertices_less_the_face_s(tmp_path, face):
    moved = np.zeros_like(face.vertices)
    moved[[100, 2000]] = (0.01, 0.02, -0.03)
    _write_obj(tmp_path / "poke.obj", face.vertices + moved)
    shapes = load_examples(face, tmp_path)
    assert list(shapes) == ["poke"]
    np.testing.assert_allclose(shapes["poke"], moved, atol=1e-12)


@pytest.mark.parametrize("case, words", [
    ("short", ["short.obj", "3 vertices", "vertex for vertex"]),
    ("twice", ["smile", "one shape per name"]),
    ("empty", ["no example shapes"]),
    ("target on a face without source indices", ["smile.target", ".obj meshes"]),
])
def test_a_bad_example_folder_names_the_file_and_what_is_wrong(tmp_path, face, case, words):
    if case == "short":
        _write_obj(tmp_path / "short.obj", face.vertices[:3])
    elif case == "twice":
        _write_obj(tmp_path / "smile.obj", face.vertices)
        (tmp_path / "smile.target").write_text("0 0.1 0 0\n")
    elif case.startswith("target"):
        (tmp_path / "smile.target").write_text("0 0.1 0 0\n")
        face = dataclasses.replace(face, source_index=None)
    with pytest.raises(ExampleError) as err:
        load_examples(face, tmp_path)
    assert all(word in str(err.value) for word in words), str(err.value)


@pytest.mark.slow
def test_calibrating_a_face_writes_a_folder_with_its_own_rig_and_reports_the_held_out_fit(tmp_path, capsys):
    """Four artist shapes of the embedded face, the right smile held out: the folder loads with the
    new rig (fold limits found on it), the FAPs the shapes show move the skin anew, those they do
    not (the nose) keep their motion, and the held-out smile fits no worse than on the shipped rig."""
    if not EXAMPLES.is_dir():
        pytest.skip(f"{EXAMPLES} is not here (../shared/assets/makehuman)")
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    for name in ("mouthSmileLeft", "jawOpen", "browInnerUp", "mouthSmileRight"):
        shutil.copy(EXAMPLES / f"{name}.target", shapes)
    out = tmp_path / "me"
    assert main(["calibrate-face", "--examples", str(shapes), "-o", str(out), "--hold-out", "mouthSmileRight"]) == 0
    text = capsys.readouterr().out
    assert "learnt from:" in text and f"--face {out}" in text
    held = float(re.search(r"held out: +median ([0-9.]+)", text).group(1))

    shipped = Runtime(load_face(), dtype=np.float64)
    smile = load_examples(load_face(), shapes)["mouthSmileRight"]
    assert held <= relative_residual(shipped, fit_faps(shipped, smile), smile) + 0.01

    mine = Runtime(load_face(out)).rig
    assert mine.fap_reach and mine.fap_follow
    def change(number: int) -> float:
        old, new = shipped.rig.fap_motions[number], mine.fap_motions.get(number, {})
        size = max(np.abs(m).max() for m in old.values())
        return max(np.abs(m - new.get(name, 0.0)).max() for name, m in old.items()) / size
    assert change(12) > 0.05 and change(3) > 0.05  # the smile's lip corner and the jaw, learnt anew
    assert max(change(n) for n in NOSE) < 0.02
