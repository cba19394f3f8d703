"""Takes play: masked FAPs update, the rest hold; a take renders to a video at its own fps."""

from __future__ import annotations

import imageio.v2 as imageio
import numpy as np
import pytest
from PIL import Image

from puppet import cli
from puppet.fap.frame import FapFrame
from puppet.fap.held import HeldFaps
from puppet.io.fapfile import read_fap, write_fap
from puppet.io.takes import TakeError
from puppet.view.demo import demo_take, run_demo
from puppet.view.rendertake import FapPlayback, render_take


def _frame(values: dict[int, float], viseme=None) -> FapFrame:
    v = np.zeros(68)
    mask = np.zeros(68, dtype=bool)
    for number, value in values.items():
        v[number - 1] = value
        mask[number - 1] = True
    if viseme is not None:
        mask[0] = True
    return FapFrame(0, v, mask, np.array(viseme if viseme else (0, 0, 0, 0)), np.zeros(6, int))


def test_unmasked_faps_hold_their_last_value():
    held = HeldFaps.neutral()
    held.update(_frame({3: 200, 31: 50}))
    held.update(_frame({31: 80}, viseme=(10, 0, 63, 0)))
    assert held.values[2] == 200 and held.values[30] == 80
    assert tuple(held.viseme[:3]) == (10, 0, 63)
    held.update(_frame({3: 0}))
    assert held.values[2] == 0 and tuple(held.viseme[:3]) == (10, 0, 63)


def test_a_take_plays_frame_by_frame_and_opens_the_mouth_where_it_says(tmp_path):
    values = np.zeros((6, 68))
    values[3:, 2] = 400
    path = tmp_path / "jaw.fap"
    write_fap(path, values, fps=30)
    playback = FapPlayback(path)
    frames = [v.copy() for v, _ in playback]
    chin = playback.face.feature_vertices["2.1"]
    assert len(frames) == 6 and playback.fps == 30
    assert np.allclose(frames[0], playback.face.vertices, atol=1e-6)
    assert frames[4][chin, 1] < playback.face.vertices[chin, 1] - 0.05


def test_render_take_writes_a_video_at_the_takes_fps(tmp_path, egl):
    values = np.zeros((5, 68))
    values[:, 2] = np.linspace(0, 500, 5)
    take = tmp_path / "take.fap"
    write_fap(take, values, fps=20)
    count = render_take(take, tmp_path / "take.mp4", size=(96, 72), progress=False)
    with imageio.get_reader(tmp_path / "take.mp4") as reader:
        frames = [frame for frame in reader]  # noqa: C416 -- list() would ask len(): inf for ffmpeg
        assert reader.get_meta_data()["fps"] == pytest.approx(20)
    assert count == len(frames) == 5
    assert frames[0].shape == (72, 96, 3)
    assert np.abs(frames[-1].astype(int) - frames[0].astype(int)).max() > 30


def test_render_antialias_smooths_the_videos_edges_when_asked(tmp_path, egl, capsys):
    """``puppet render --antialias fxaa`` draws the frames through the FXAA pass: the same take
    as drawn by default (this GL's choice, none on a software rasteriser) differs at edges only."""
    values = np.zeros((2, 68))
    values[:, 2] = 300
    take = tmp_path / "take.fap"
    write_fap(take, values, fps=20)
    videos = {mode: tmp_path / f"{mode}.mp4" for mode in ("fxaa", "none")}
    for mode, video in videos.items():
        assert cli.main(["render", str(take), "-o", str(video), "--size", "160x120", "--antialias", mode]) == 0
    fxaa, plain = (_first_frame(videos[mode]) for mode in ("fxaa", "none"))
    changed = np.abs(fxaa - plain).max(axis=2) > 16
    assert 0 < changed.mean() < 0.1  # some edge pixels, a small part of the frame


def _first_frame(video) -> np.ndarray:
    with imageio.get_reader(video) as reader:
        return reader.get_data(0).astype(int)


def test_the_shipped_demo_take_is_a_standard_fap_file():
    take = read_fap(demo_take())
    assert take.fps == 25 and len(take) == take.declared_frames > 50
    assert take.mask[:, 0].all() and take.mask[:, 1].all()
    assert len(set(take.viseme[:, 0])) >= 8


def test_render_take_refuses_an_empty_take_and_leaves_no_video(tmp_path, egl):
    take = tmp_path / "empty.fap"
    take.write_text("2.1 empty 25 0\n")
    with pytest.raises(TakeError, match="holds no frames"):
        render_take(take, tmp_path / "empty.mp4", size=(32, 32), progress=False)
    assert not list(tmp_path.glob("*.mp4"))


def test_puppet_render_reports_a_bad_take_in_one_line(tmp_path, capsys):
    take = tmp_path / "bad.fap"
    take.write_text("2.1 bad 25 1\n0 0 1\n")
    assert cli.main(["render", str(take), "-o", str(tmp_path / "bad.mp4")]) == 2
    assert capsys.readouterr().err.strip() == f"puppet render: {take}:2: expected a mask line of 68 flags (0 or 1), found 3 flags"
    assert cli.main(["render", str(tmp_path / "missing.fap"), "-o", str(tmp_path / "x.mp4")]) == 2
    assert "missing.fap: no such take (expected a take folder or a .fap file)" in capsys.readouterr().err


def test_the_demo_writes_a_video_and_a_still(tmp_path, egl):
    video, still = run_demo(tmp_path, size=(64, 48))
    with imageio.get_reader(video) as reader:
        assert sum(1 for _ in reader) == len(read_fap(demo_take()))
    with Image.open(still) as picture:
        assert picture.size == (128, 48)


def test_the_shipped_demo_take_is_what_the_tool_makes_today(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "demo_take.fap"
    subprocess.run([sys.executable, str(root / "tools" / "builders" / "make_demo_take.py"), "--out", str(out)],
                   check=True, capture_output=True, env={"PYTHONPATH": str(root), "PATH": ""})
    assert out.read_bytes() == demo_take().read_bytes(), "run tools/builders/make_demo_take.py"


def test_render_shows_a_bar_when_asked_and_always_ends_with_a_summary_line(tmp_path, egl, capsys):
    frames = np.zeros((6, 68))
    frames[:, 2] = np.linspace(0, 400, 6)
    write_fap(tmp_path / "t.fap", frames, fps=25)
    assert render_take(tmp_path / "t.fap", tmp_path / "bar.mp4", size=(64, 48), progress=True) == 6
    assert cli.main(["render", str(tmp_path / "t.fap"), "-o", str(tmp_path / "t.mp4"), "--size", "64x48"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith(f"{tmp_path / 't.mp4'}: 6 frames in ") and "frames/s" in out[0]
