"""A take exports to a valid .glb whose morph targets and weights replay the take."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from puppet.io.fapfile import write_fap
from puppet.view.gltf import export_glb
from puppet.view.rendertake import FapPlayback

FPS = 25
SIZES = {5126: 4, 5125: 4}
WIDTH = {"SCALAR": 1, "VEC3": 3}
DTYPE = {5126: "<f4", 5125: "<u4"}


def _read_glb(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A and json_len % 4 == 0
    gltf = json.loads(data[20:20 + json_len])
    start = 20 + json_len
    bin_len, bin_type = struct.unpack_from("<II", data, start)
    assert bin_type == 0x004E4942 and bin_len % 4 == 0 and start + 8 + bin_len == len(data)
    return gltf, data[start + 8:start + 8 + bin_len]


def _accessor(gltf: dict, blob: bytes, index: int) -> np.ndarray:
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    offset = view["byteOffset"] + acc.get("byteOffset", 0)
    assert offset % SIZES[acc["componentType"]] == 0 and view["byteOffset"] % 4 == 0
    width = WIDTH[acc["type"]]
    nbytes = acc["count"] * width * SIZES[acc["componentType"]]
    assert nbytes <= view["byteLength"] and view["byteOffset"] + view["byteLength"] <= len(blob)
    array = np.frombuffer(blob, DTYPE[acc["componentType"]], acc["count"] * width, offset)
    array = array.reshape(acc["count"], width)
    if "min" in acc:
        assert np.array_equal(np.float32(acc["min"]), array.min(axis=0))
        assert np.array_equal(np.float32(acc["max"]), array.max(axis=0))
    return array


@pytest.fixture(scope="module")
def take(tmp_path_factory) -> Path:
    values = np.zeros((10, 68))
    values[:, 2] = np.linspace(0, 600, 10)  # FAP 3 open_jaw, ramping
    values[:, 11] = 80 * np.sin(np.linspace(0, 3, 10))  # FAP 12, another motion
    path = tmp_path_factory.mktemp("take") / "take.fap"
    write_fap(path, values, fps=FPS)
    return path


@pytest.fixture(scope="module")
def played(take) -> tuple[list[np.ndarray], FapPlayback]:
    playback = FapPlayback(take)
    return [v.copy() for v, _ in playback], playback


@pytest.mark.parametrize("mode", ["morph", "frames"])
def test_the_glb_replays_the_take_within_the_reported_error(take, played, tmp_path, mode):
    frames, playback = played
    out = tmp_path / "take.glb"
    info = export_glb(take, out, mode=mode)
    assert info["frames"] == 10 and info["bytes"] == out.stat().st_size
    assert info["targets"] == (10 if mode == "frames" else info["targets"])
    assert 1 <= info["targets"] <= 32
    gltf, blob = _read_glb(out)
    assert gltf["asset"]["version"] == "2.0" and gltf["scenes"][gltf["scene"]]["nodes"] == [0]
    prim = gltf["meshes"][0]["primitives"][0]
    face = playback.face
    n = len(face.vertices)
    rest = _accessor(gltf, blob, prim["attributes"]["POSITION"])
    normals = _accessor(gltf, blob, prim["attributes"]["NORMAL"])
    colors = _accessor(gltf, blob, prim["attributes"]["COLOR_0"])
    tris = _accessor(gltf, blob, prim["indices"]).reshape(-1, 3)
    assert rest.shape == normals.shape == colors.shape == (n, 3)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-5)
    assert np.allclose(colors, face.colors, atol=1e-6)
    assert np.array_equal(tris, face.triangles)
    assert "min" in gltf["accessors"][prim["attributes"]["POSITION"]]
    mat = gltf["materials"][prim["material"]]["pbrMetallicRoughness"]
    assert mat["metallicFactor"] == 0 and mat["roughnessFactor"] == 0.6

    targets = []
    for target in prim["targets"]:
        assert "min" in gltf["accessors"][target["POSITION"]]
        targets.append(_accessor(gltf, blob, target["POSITION"]))
    targets = np.stack(targets)
    assert len(targets) == info["targets"]
    sampler = gltf["animations"][0]["samplers"][0]
    assert sampler["interpolation"] == ("LINEAR" if mode == "morph" else "STEP")
    times = _accessor(gltf, blob, sampler["input"]).ravel()
    assert np.allclose(times, np.arange(10) / FPS)
    weights = _accessor(gltf, blob, sampler["output"]).reshape(10, len(targets))
    if mode == "frames":
        assert np.array_equal(weights, np.eye(10))
    errors = [np.linalg.norm(rest + np.tensordot(weights[i], targets, 1) - frames[i], axis=1).max()
              for i in range(10)]
    assert max(errors) <= info["max_error"] * (1 + 1e-4) + 1e-6
    size = np.ptp(face.vertices, axis=0).max()
    assert info["max_error"] < 1.01e-3 * size  # the default tolerance, 1/1000 of the head
    jaw = max(np.linalg.norm(f - frames[0], axis=1).max() for f in frames)
    assert jaw > 10 * info["max_error"]  # the take really moves, more than the error


def test_a_take_folder_exports_and_frames_mode_is_guarded(take, tmp_path):
    folder = tmp_path / "t_001"
    folder.mkdir()
    shutil.copy(take, folder / "take.fap")
    (folder / "take.json").write_text(json.dumps({"name": "t", "fps": FPS}))
    info = export_glb(folder, tmp_path / "a.glb", mode="frames", max_frames=4)
    assert info["frames"] == 4 and info["targets"] == 4
    with pytest.raises(ValueError):
        export_glb(take, tmp_path / "b.glb", mode="sideways")


def _validator() -> tuple[str, str] | None:
    """(node, path to the gltf-validator package), from $GLTF_VALIDATOR or node's own lookup."""
    node = shutil.which("node")
    if node is None:
        return None
    candidates = [os.environ.get("GLTF_VALIDATOR", ""), "gltf-validator"]
    for name in filter(None, candidates):
        found = subprocess.run([node, "-e", f"console.log(require.resolve({json.dumps(name)}))"],
                               capture_output=True, text=True, timeout=30, check=False)
        if found.returncode == 0:
            return node, found.stdout.strip()
    return None


def test_the_khronos_validator_finds_no_errors(take, tmp_path):
    validator = _validator()
    if validator is None:
        pytest.skip("no node or no gltf-validator package (npm install gltf-validator somewhere "
                    "and set GLTF_VALIDATOR=/that/node_modules/gltf-validator)")
    node, package = validator
    script = ("const v = require(process.argv[1]); const fs = require('fs');"
              "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))"
              ".then(r => console.log(JSON.stringify(r.issues)))"
              ".catch(e => { console.error(e); process.exit(2); });")
    for mode in ("morph", "frames"):
        out = tmp_path / f"{mode}.glb"
        export_glb(take, out, mode=mode)
        run = subprocess.run([node, "-e", script, package, str(out)], capture_output=True,
                             text=True, timeout=60, check=False)
        assert run.returncode == 0, run.stderr
        issues = json.loads(run.stdout)
        assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


def test_the_vertex_error_is_said_in_millimetres_on_the_default_face_and_in_the_files_units_else():
    from puppet.face.default import DEFAULT_UNIT_MM
    from puppet.view.gltf import error_words

    assert error_words(0.0028, 2.86, DEFAULT_UNIT_MM) == "largest vertex error 0.28 mm (0.098% of the face's 286 mm size)"
    assert error_words(0.0028, 2.86) == ("largest vertex error 0.0028 mesh units (the face file's own unit; "
                                         "0.098% of the face's 2.86-unit size)")


def test_puppet_export_says_each_step_only_after_its_inputs_are_read(take, tmp_path, capsys):
    """Issue 38: export's half minute on a long take is not silent: three steps on stderr, each as
    it starts; a take that cannot be read is one line and no step."""
    from puppet.cli import main

    assert main(["export", str(take), "-o", str(tmp_path / "t.glb")]) == 0
    captured = capsys.readouterr()
    assert [line.split(":")[0] for line in captured.err.splitlines()] == [f"export {k}/3" for k in (1, 2, 3)]
    assert "t.glb: 10 frames" in captured.out
    assert main(["export", str(tmp_path / "none.fap"), "-o", str(tmp_path / "u.glb")]) != 0
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "none.fap" in lines[0], lines
