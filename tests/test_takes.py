"""Takes are numbered folders that never overwrite one another and survive a killed recorder."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from devices.base import Sample
from puppet.io.takes import TakeError, TakeRecorder, next_take_folder, open_take

ROOT = Path(__file__).resolve().parents[1]


def test_takes_are_numbered_and_never_overwrite(tmp_path):
    folders = [next_take_folder(tmp_path, "scene") for _ in range(3)]
    assert [f.name for f in folders] == ["scene_001", "scene_002", "scene_003"]
    (tmp_path / "scene_007").mkdir()
    assert next_take_folder(tmp_path, "scene").name == "scene_008"
    with pytest.raises(TakeError, match="take name"):
        next_take_folder(tmp_path, "../escape")


def test_a_take_records_frames_samples_and_metadata(tmp_path):
    mapping = ROOT / "mappings" / "arduino_sliders.yaml"
    with TakeRecorder(tmp_path, "hello", 30, mapping_path=mapping, devices={"box": "sim://joystick"}) as rec:
        for i in range(10):
            rec.sample(Sample(i * 1000, "box", {"ch0": float(i)}))
            fap = np.zeros(68)
            fap[2] = 10 * i
            rec.frame(fap, viseme=(10, 0, 63), expression=(1, 40, 0, 0))
    take = open_take(rec.folder)
    assert take.meta["fps"] == 30 and take.meta["frames"] == 10 and take.meta["samples"] == 10
    assert take.meta["mapping_text"] == mapping.read_text()
    stream = take.stream()
    assert len(stream) == 10 and stream.fps == 30
    np.testing.assert_array_equal(stream.values[:, 2], 10 * np.arange(10))
    assert tuple(stream.viseme[3][:3]) == (10, 0, 63) and tuple(stream.expression[3][:2]) == (1, 40)
    assert [s.values["ch0"] for s in take.samples()] == list(range(10))


def test_a_killed_recorder_leaves_every_complete_frame_and_sample(tmp_path):
    script = f"""
import os, signal, numpy as np
from devices.base import Sample
from puppet.io.takes import TakeRecorder
rec = TakeRecorder({str(tmp_path)!r}, "crash", 25)
for i in range(7):
    rec.sample(Sample(i, "box", {{"ch0": float(i)}}))
    rec.frame(np.full(68, float(i)))
print(rec.folder, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == -signal.SIGKILL
    take = open_take(run.stdout.strip())
    assert take.meta["frames"] is None, "the recorder never finished"
    stream = take.stream()
    assert len(stream) == 7 and stream.declared_frames == 7
    np.testing.assert_array_equal(stream.values[:, 5], np.arange(7))
    assert len(list(take.samples())) == 7


def test_a_folder_that_is_not_a_take_says_so(tmp_path):
    with pytest.raises(TakeError, match="not a take"):
        open_take(tmp_path)
    with pytest.raises(TakeError, match="no such take folder"):
        open_take(tmp_path / "take_009")
    with pytest.raises(TakeError, match="fps 24"):
        TakeRecorder(tmp_path, "x", 24)
