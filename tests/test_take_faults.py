"""A take folder that is damaged (a part deleted, garbled, binary, nested without end, cut off by a
kill) is one clear error in every command that reads it, never a traceback, and nothing on disk
is rewritten: replay, render, export and play check the folder, not only its take.fap."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from puppet import cli
from puppet.errors import PuppetError
from puppet.io.fapfile import COUNT_WIDTH, read_fap, write_fap
from puppet.io.takes import TakeError, open_take, take_fap
from puppet.live.arkit import import_csv
from puppet.live.retake import retake
from puppet.view.rendertake import FapPlayback


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    """A real take (an imported CSV: log, metadata with the mapping's state, .fap), 40 frames."""
    root = tmp_path_factory.mktemp("takes")
    names = ["JawOpen", "MouthSmileLeft", "BrowInnerUp"]
    rows = [f"00:00:00:{i:02d}.000,3," + ",".join(f"{(i * (k + 2) % 11) / 10:.2f}" for k in range(3))
            for i in range(60)]
    csv = root / "face.csv"
    csv.write_text("Timecode,BlendShapeCount," + ",".join(names) + "\n" + "\n".join(rows) + "\n")
    return import_csv(csv, root / "takes", "good", fps=30)


def _meta(folder: Path, **changes) -> None:
    meta = json.loads((folder / "take.json").read_text())
    meta.update(changes)
    (folder / "take.json").write_text(json.dumps(meta))


def _append(name: str, data: bytes):
    def change(folder: Path) -> None:
        with open(folder / name, "ab") as file:
            file.write(data)
    return change


DAMAGE = {
    "samples.jsonl deleted": (lambda f: (f / "samples.jsonl").unlink(), "no samples.jsonl"),
    "take.fap deleted": (lambda f: (f / "take.fap").unlink(), "no take.fap"),
    "take.json holds []": (lambda f: (f / "take.json").write_text("[]"), "expected a JSON object"),
    "take.json is binary": (lambda f: (f / "take.json").write_bytes(bytes(range(256)) * 4), "not UTF-8"),
    "take.json nests 100k deep": (lambda f: (f / "take.json").write_text("[" * 100_000 + "]" * 100_000),
                                  "nested too deeply"),
    "take.json is cut off": (lambda f: (f / "take.json").write_text('{"name": "x", "fps'), "not valid JSON"),
    "fps is a list": (lambda f: _meta(f, fps=[30]), "'fps': expected one of"),
    "t0_ns is a string": (lambda f: _meta(f, t0_ns="0"), "'t0_ns': expected an integer"),
    "mapping_state is a string": (lambda f: _meta(f, mapping_state="garbled"), "'mapping_state'"),
    "mapping_state channels garbled": (
        lambda f: _meta(f, mapping_state={"seq": 0, "channels": {"csv.JawOpen": {"raw": "x"}}}),
        "mapping_state"),
    "devices is a list": (lambda f: _meta(f, devices=["csv"]), "'devices'"),
    "a log line 100k deep": (_append("samples.jsonl", b"[" * 100_000 + b"]" * 100_000 + b"\n"),
                             "samples.jsonl: unreadable"),
    "a list where a log value belongs": (
        _append("samples.jsonl", b'{"t_ns": 10, "device": "csv", "values": {"JawOpen": [1]}}\n'),
        "samples.jsonl: unreadable"),
    "a binary log line": (_append("samples.jsonl", bytes(range(256)) + b"\n"), "samples.jsonl: unreadable"),
}


@pytest.fixture(params=sorted(DAMAGE))
def damaged(request, good, tmp_path):
    folder = tmp_path / "damaged_001"
    shutil.copytree(good, folder)
    change, needle = DAMAGE[request.param]
    change(folder)
    return folder, needle, {p.name: p.read_bytes() for p in folder.iterdir()}


def test_replay_of_a_damaged_take_is_one_clear_error(damaged, tmp_path, capsys):
    folder, needle, before = damaged
    code = cli.main(["replay", str(folder), "-o", str(tmp_path / "again.fap"), "--no-window"])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    if needle == "no take.fap":  # the log is all a replay needs: it runs, and says why it cannot compare
        assert code == 1 and "not compared: the recorded take.fap is unreadable" in out
    else:
        assert code == 2 and len(lines) == 1 and lines[0].startswith("puppet replay: "), err
        assert needle in lines[0], lines[0]
    assert "Traceback" not in err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # nothing rewritten


@pytest.mark.parametrize("command", ["render", "export"])
def test_render_and_export_check_the_folder_not_only_its_fap(damaged, tmp_path, capsys, command):
    folder, needle, before = damaged
    out = tmp_path / ("x.mp4" if command == "render" else "x.glb")
    code = cli.main([command, str(folder), "-o", str(out)])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if needle.startswith(("no samples", "samples.jsonl", "mapping_state")):
        assert code == 0 and out.stat().st_size > 0  # drawing needs the .fap, not the log or its state
    else:
        assert code == 2 and len(err.strip().splitlines()) == 1 and needle in err, err
        assert not out.exists()
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


class _WindowOpened(Exception):
    """Raised by a stand-in for the window: the take passed every check."""


def _open_window(*args, **kwargs):
    raise _WindowOpened


def test_play_checks_the_folder_before_its_window_opens(damaged, capsys, monkeypatch):
    from puppet.view import window

    folder, needle, before = damaged
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr(window, "open_window", _open_window)
    capsys.readouterr()
    if needle.startswith(("no samples", "samples.jsonl", "mapping_state")):
        with pytest.raises(_WindowOpened):  # playing needs the .fap, not the log or its state
            cli.main(["play", str(folder)])
    else:
        try:
            code = cli.main(["play", str(folder)])
        except SystemExit as exit_:
            code = exit_.code
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1 and needle in err, err
        assert err.startswith("puppet play: ") and "Traceback" not in err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def test_a_take_fap_without_take_json_still_renders_with_a_warning(good, tmp_path, capsys, egl):
    folder = tmp_path / "bare_001"
    shutil.copytree(good, folder)
    (folder / "take.json").unlink()
    with pytest.warns(UserWarning, match="no take.json"):
        assert take_fap(folder) == folder / "take.fap"
    capsys.readouterr()
    assert cli.main(["render", str(folder), "-o", str(tmp_path / "bare.mp4")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("puppet render: warning: ") and "no take.json" in err[0]
    assert (tmp_path / "bare.mp4").stat().st_size > 0
    with pytest.raises(TakeError, match="not a take"):
        open_take(folder)  # but it cannot be replayed from its log


def test_replay_tells_an_unreadable_recorded_fap_apart_from_differs(good, tmp_path, capsys):
    folder = tmp_path / "unreadable_001"
    shutil.copytree(good, folder)
    (folder / "take.fap").write_text("garbage\n")
    result = retake(folder, tmp_path / "again.fap")
    assert result.identical is None and "the recorded take.fap is unreadable" in result.unreadable
    assert len(read_fap(tmp_path / "again.fap")) == open_take(good).meta["frames"]  # the take, recovered
    assert cli.main(["replay", str(folder), "-o", str(tmp_path / "cli.fap"), "--no-window"]) == 1
    out = capsys.readouterr().out
    assert "not compared: the recorded take.fap is unreadable" in out and "DIFFERS" not in out


def _kill(folder: Path, keep: int, partial: int, count: int) -> None:
    """Leave the take as a recorder killed while writing frame ``keep`` would: ``keep`` complete
    frames, ``partial`` bytes of the next, the header's count at ``keep``, the log running ahead
    (the session logs an entry before it writes the frames that entry makes due), and take.json
    still saying incomplete; ``count`` one short is a kill between a frame and its count."""
    data = (folder / "take.fap").read_bytes()
    lines = data.split(b"\n")
    head = lines[0].split()
    header = b" ".join(head[:-1]) + b" " + str(count).ljust(COUNT_WIDTH).encode()
    frame_bytes = b"".join(line + b"\n" for line in lines[1 + 2 * keep:3 + 2 * keep])
    body = b"".join(line + b"\n" for line in lines[1:1 + 2 * keep])
    (folder / "take.fap").write_bytes(header + b"\n" + body + frame_bytes[:partial])
    _meta(folder, complete=False, frames=None, samples=None)


@pytest.mark.parametrize("keep, partial, count", [(10, 0, 10), (10, 7, 10), (10, 150, 10), (25, 200, 25),
                                                  (0, 40, 0), (12, 0, 11)])
def test_a_take_killed_mid_write_replays_to_its_last_complete_frame(good, tmp_path, keep, partial, count):
    """Before: the log, which runs ahead of the .fap, replayed one frame more than was recorded."""
    folder = tmp_path / "killed_001"
    shutil.copytree(good, folder)
    _kill(folder, keep, partial, count)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        recorded = read_fap(folder / "take.fap")
        result = retake(folder, tmp_path / "again.fap")
    assert len(recorded) == keep
    assert result.frames == keep and result.identical, (result, keep)
    np.testing.assert_array_equal(read_fap(tmp_path / "again.fap").values, recorded.values)


def test_a_complete_take_still_differs_when_it_does(good, tmp_path):
    folder = tmp_path / "edited_001"
    shutil.copytree(good, folder)
    stream = read_fap(folder / "take.fap")
    stream.values[5, 2] += 1
    write_fap(folder / "take.fap", stream)
    assert retake(folder, tmp_path / "again.fap").identical is False


def test_a_take_with_values_beyond_every_range_plays_and_replays_unchanged(good, tmp_path):
    """The reader no longer clamps: playing or replaying a take never rewrites what it holds."""
    fap = tmp_path / "wild.fap"
    values = np.zeros((4, 68))
    values[:, 48], values[:, 13], values[:, 2] = 56298, -1242, 1e6
    write_fap(fap, values)
    before = fap.read_bytes()
    frames = list(FapPlayback(fap))
    assert len(frames) == 4 and all(np.isfinite(v).all() and np.isfinite(n).all() for v, n in frames)
    assert fap.read_bytes() == before and read_fap(fap).values[0, 48] == 56298


def test_every_take_error_is_a_puppet_error():
    assert issubclass(TakeError, PuppetError) and issubclass(TakeError, ValueError)


def test_the_window_table_holds_extreme_takes_without_overflow(tmp_path, face):
    """The player's float32 table keeps what the face can show: 1e300 neither overflows nor warns."""
    from puppet.runtime.runtime import Runtime
    from puppet.view.window import HeldTable

    fap = tmp_path / "huge.fap"
    values = np.zeros((3, 68))
    values[:, 2], values[:, 48], values[:, 18] = 1e300, -1e300, 1e20
    write_fap(fap, values)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        table = HeldTable(fap, Runtime(face))
        assert table.ensure(3)
        vertices, normals = table.mesh(2)
    assert np.isfinite(vertices).all() and np.isfinite(normals).all()
    assert read_fap(fap).values[0, 2] == 1e300


KILLED_RECORDER = """
import os, signal, sys
from devices.base import Sample
from puppet.live.mappingfile import load_mapping
from puppet.live.takeclock import TakeClock, default_muscle_faps
from puppet.io.takes import TakeRecorder
mapping = load_mapping({mapping!r})
rec = TakeRecorder({root!r}, "fast", 25, mapping_path={mapping!r}, devices={{"box": "sim://joystick"}},
                   extra={{"t0_ns": 0, "hold_ns": None, "mapping_state": mapping.snapshot()}})
clock = TakeClock(mapping, rec.frame, 0, 25, encode_muscles=default_muscle_faps)
print(rec.folder, flush=True)
for i in range(100_000):  # 5,000 samples/s, as the session records them: log, then the frames due
    sample = Sample(i * 200_000, "box", {{"ch0": float(i % 1024), "ch1": 512.0}})
    rec.sample(sample)
    if clock.due(sample.t_ns - 1) and clock.frames == {kill_at}:
        os.kill(os.getpid(), signal.SIGKILL)  # logged, its frame not yet written
    clock.apply(sample)
"""


def test_a_5000_hz_take_killed_between_its_log_and_its_frame_replays_what_it_recorded(tmp_path):
    """The reproducer: the log held the sample that made frame 10 due, the .fap had 10 frames;
    the replay used to write 11."""
    import os
    import signal
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    script = KILLED_RECORDER.format(mapping=str(root / "mappings" / "arduino_sliders.yaml"),
                                    root=str(tmp_path / "takes"), kill_at=10)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(root)}, timeout=120)
    assert run.returncode == -signal.SIGKILL, run.stderr
    folder = Path(run.stdout.strip())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert len(read_fap(folder / "take.fap")) == 10
        result = retake(folder, tmp_path / "again.fap")
    assert result.frames == 10 and result.identical
