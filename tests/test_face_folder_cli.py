"""A face rigged by ``puppet rig ... -o FOLDER/`` works everywhere ``--face`` is taken, and a bare
mesh says how to rig it."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from puppet.cli import main
from puppet.face.folder import load_folder_rig
from puppet.face.load import load_face
from puppet.face.meshfile import write_bare_obj
from puppet.io.fapfile import write_fap
from puppet.runtime.musclesolver import folded_triangles
from puppet.runtime.runtime import Runtime


@pytest.fixture(scope="module")
def rigged(tmp_path_factory):
    """The default face's skin and teeth written as a bare OBJ, its landmarks as JSON, rigged into a folder."""
    root = tmp_path_factory.mktemp("rigged")
    face = load_face()
    mesh = write_bare_obj(root / "head.obj", face.vertices, face.triangles)
    points = root / "points.json"
    points.write_text(json.dumps(face.feature_vertices))
    said = io.StringIO()
    with contextlib.redirect_stderr(said):
        assert main(["rig", str(mesh), "--landmarks", str(points), "-o", str(root / "head")]) == 0
    (root / "rig_stderr.txt").write_text(said.getvalue())
    take = root / "take.fap"
    frames = np.zeros((10, 68))
    frames[:, 2] = np.linspace(0, 300, 10)  # open_jaw
    write_fap(take, frames, fps=25)
    return root


def test_puppet_rig_says_each_step_as_it_starts(rigged):
    """The minute a big mesh takes is not silent: each step is said on stderr as it begins."""
    steps = (rigged / "rig_stderr.txt").read_text().splitlines()
    assert [line.split(":")[0] for line in steps] == [f"rig {k}/4" for k in range(1, 5)]
    assert "vertices" in steps[0] and "crease" in steps[1] and "fold limits" in steps[2] and "guard" in steps[3]


def test_the_folder_holds_mesh_feature_points_and_rig_and_loads_with_its_own_rig(rigged):
    folder = rigged / "head"
    assert {p.name for p in folder.iterdir()} == {"face.obj", "face.json", "face.rig"}
    face = load_face(folder)
    assert set(face.feature_points) == set(load_face().feature_points)
    assert load_folder_rig(folder).face_hash == face.content_hash  # the folder reads back the mesh its rig is for
    runtime = Runtime(face)
    assert runtime.rig.face_hash == face.content_hash
    moved = runtime.deform_faps({"open_jaw": 300}) - face.vertices
    assert np.abs(moved).max() > 0


def test_a_rigged_face_has_fold_limits_of_its_own_and_its_lids_still_close(rigged):
    """Rigged from a bare mesh, the default face folded from open_jaw 385 MNS; its rig now caps
    each FAP where it folds (at pose time) but leaves the upper lids' closing open."""
    face = load_face(rigged / "head")
    runtime = Runtime(face)
    assert runtime.rig.fap_reach[3][1] < 1080 and runtime.rig.fap_reach[19][1] == np.inf
    wide = runtime.deform_faps({"open_jaw": 1080})
    assert not folded_triangles(face.vertices, wide, face.triangles).any()


def test_render_and_export_take_the_folder(rigged, capsys, egl):
    assert main(["render", str(rigged / "take.fap"), "-o", str(rigged / "take.mp4"), "--size", "160x120",
                 "--face", str(rigged / "head")]) == 0
    assert (rigged / "take.mp4").stat().st_size > 0
    assert main(["export", str(rigged / "take.fap"), "-o", str(rigged / "take.glb"), "--face", str(rigged / "head")]) == 0
    assert (rigged / "take.glb").stat().st_size > 0


def test_a_bare_mesh_as_face_says_how_to_rig_it(rigged, capsys):
    assert main(["export", str(rigged / "take.fap"), "-o", str(rigged / "x.glb"), "--face", str(rigged / "head.obj")]) == 2
    err = capsys.readouterr().err
    assert "puppet rig" in err and "--landmarks" in err and len(err.strip().splitlines()) == 1
    assert not (rigged / "x.glb").exists()


def test_a_rig_file_name_still_writes_the_rig_alone(rigged):
    out = rigged / "alone.rig"
    assert main(["rig", str(rigged / "head.obj"), "--landmarks", str(rigged / "points.json"), "-o", str(out)]) == 0
    assert out.is_file()


@pytest.mark.parametrize("command", ["play", "replay", "live"])
def test_play_replay_and_live_take_the_folder(rigged, monkeypatch, command):
    """The window commands hand the folder's face, with its own rig, to the window they open."""
    import puppet.view.livewindow
    import puppet.view.window

    seen = {}
    if command == "live":
        monkeypatch.setattr(puppet.view.livewindow, "run_live", lambda mapping, **kw: seen.update(kw))
        argv = ["live", "--mapping", "arduino_sliders", "--device", "box=sim://joystick"]
    else:
        monkeypatch.setattr(puppet.view.window, "play_take", lambda take, **kw: seen.update(kw))
        argv = [command, str(rigged / "take.fap")]
    assert main([*argv, "--face", str(rigged / "head")]) == 0
    face = seen["face"]
    assert face.content_hash == load_face(rigged / "head").content_hash and face.feature_points


def test_the_live_window_performs_the_folder_face(rigged, tmp_path, headless_window):
    """``puppet live --face FOLDER/``'s loop, headless: the slider box moves the rigged face."""
    from puppet.io.shipped import shipped_mappings
    from puppet.view.livewindow import LiveView, open_session

    window = headless_window((160, 120))
    session = open_session(shipped_mappings()["arduino_sliders"], devices={"box": "sim://joystick?rate=200"},
                           record_root=tmp_path, face=load_face(rigged / "head"))
    live = LiveView(session, window)
    try:
        first = session.frame().vertices.copy()
        for _ in range(10):
            live.step()
        pixels = np.frombuffer(window.fbo.read(components=3), dtype=np.uint8).reshape(120, 160, 3)
        assert np.ptp(pixels[60].astype(int)) > 60  # a face across the middle row
        assert np.abs(session.frame().vertices - first).max() > 0  # and it moves
    finally:
        live.close()
        session.close()
