"""A face's own ARKit route (``puppet.live.arkitroute``): ``calibrate-face`` with ARKit-named
examples (a perfect-sync GLB's morph targets) writes the face's ARKit vectors and the two routes
into its folder; they load as mappings, keep the default face's vectors for blendshapes the face
has no example of, and move the calibrated face like its artist's shapes, closer than the shipped
route (solved on the default face) does."""

from __future__ import annotations

import json
import re

import jsonschema
import numpy as np
import pytest
import yaml
from gltfface import ARKIT_SHAPES, shapes, write_head
from test_gltf_faces import glb_landmarks

from devices.base import Sample
from puppet import load_mapping
from puppet.cli import main
from puppet.face.examples import load_examples
from puppet.face.load import load_face
from puppet.io.shipped import mappings_folder
from puppet.live.arkitroute import remove_face_route, shipped_vectors, write_face_route
from puppet.runtime.fapcalibration import relative_residual
from puppet.runtime.runtime import Runtime

SCHEMA = json.loads((mappings_folder() / "schema.json").read_text())


def _through(route, shape: str, runtime: Runtime, displacement: np.ndarray) -> float:
    """The relative residual of the calibrated face posed by ``shape`` = 1 sent through a CSV route."""
    mapping = load_mapping(route)
    mapping.feed(Sample(1, "csv", {shape[0].upper() + shape[1:]: 1.0}))
    return relative_residual(runtime, mapping.pose().fap, displacement)


def test_a_face_route_has_its_own_vectors_and_the_default_face_s_for_the_rest(tmp_path):
    own = {"description": "test", "faps": {"jawOpen": {"open_jaw": 321, "raise_b_midlip": 3}},
           "residual": {"jawOpen": 0.123}}
    written = write_face_route(own, tmp_path, "face 'me' (me/)")
    assert [p.name for p in written] == ["arkit_faps.json", "arkit_csv.yaml", "arkit_osc.yaml"]
    assert json.loads((tmp_path / "arkit_faps.json").read_text()) == own
    csv = (tmp_path / "arkit_csv.yaml").read_text()
    assert "for face 'me' (me/)" in csv and "schema.json" not in csv
    assert "# jawOpen: leaves 0.12 of the example unexplained" in csv
    assert "- {fap: open_jaw, source: csv.JawOpen, range: [0, 321]}" in csv
    assert "raise_b_midlip, source: csv.JawOpen" not in csv  # under 5 FAPU: left out
    assert "# mouthSmileLeft: no example of this face; the default face's vector" in csv
    smile = shipped_vectors()["faps"]["mouthSmileLeft"]["raise_l_cornerlip"]
    assert f"- {{fap: raise_l_cornerlip, source: csv.MouthSmileLeft, range: [0, {smile:g}]}}" in csv
    for name in ("arkit_csv.yaml", "arkit_osc.yaml"):
        jsonschema.validate(yaml.safe_load((tmp_path / name).read_text()), SCHEMA)
        mapping = load_mapping(tmp_path / name)
        assert mapping.devices and all(c.targets for c in mapping.channels())
    mapping = load_mapping(tmp_path / "arkit_csv.yaml")
    mapping.feed(Sample(1, "csv", {"JawOpen": 0.5}))
    assert mapping.pose().fap[3 - 1] == pytest.approx(160.5)


def test_a_face_route_is_removed_whole_and_nothing_else(tmp_path):
    own = {"description": "test", "faps": {"jawOpen": {"open_jaw": 321}}, "residual": {"jawOpen": 0.1}}
    written = write_face_route(own, tmp_path, "face 'me' (me/)")
    (tmp_path / "face.rig").write_text("{}")
    assert remove_face_route(tmp_path) == written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["face.rig"]
    assert remove_face_route(tmp_path) == []


@pytest.mark.slow
def test_calibrate_face_writes_the_face_s_own_arkit_route_which_beats_the_shipped_one(tmp_path, capsys):
    """A GLB of the embedded face with five of its artist's ARKit shapes, rigged from its landmarks
    and calibrated from the GLB with one shape held out: the folder's route loads, and a smile sent
    through it reproduces the artist's smile on the calibrated face closer than the shipped route."""
    if not ARKIT_SHAPES.is_dir():
        pytest.skip(f"{ARKIT_SHAPES} is not here (../shared/assets/makehuman)")
    names = ("jawOpen", "mouthSmileLeft", "mouthSmileRight", "browInnerUp", "eyeBlinkLeft")
    head = write_head(tmp_path / "head.glb", shapes(names))
    landmarks = tmp_path / "points.json"
    landmarks.write_text(json.dumps(glb_landmarks()))
    out = tmp_path / "me"
    assert main(["rig", str(head), "--landmarks", str(landmarks), "-o", str(out)]) == 0
    capsys.readouterr()
    assert main(["calibrate-face", "--face", str(out), "--examples", str(head), "-o", str(out),
                 "--hold-out", "mouthSmileRight"]) == 0
    text = capsys.readouterr().out
    assert f"--mapping {out / 'arkit_osc.yaml'}" in text and f"--mapping {out / 'arkit_csv.yaml'}" in text
    own = json.loads((out / "arkit_faps.json").read_text())
    assert sorted(own["faps"]) == sorted(names)
    face = load_face(out)
    runtime = Runtime(face, dtype=np.float64)
    examples = load_examples(face, head)
    figures = {}
    for shape in ("mouthSmileLeft", "mouthSmileRight"):
        figures[shape] = (_through(out / "arkit_csv.yaml", shape, runtime, examples[shape]),
                          _through(mappings_folder() / "arkit_csv.yaml", shape, runtime, examples[shape]))
        assert figures[shape][0] < figures[shape][1] - 0.01, figures
        assert figures[shape][0] == pytest.approx(own["residual"][shape], abs=0.03), figures
    print("own route vs shipped route, relative residual:", figures,
          "held out:", re.search(r"held out: .*", text).group(0))
