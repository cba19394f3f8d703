"""Live Link Face CSVs: timecodes, clear errors, and an import that becomes a take."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml

from puppet.fap.units import AU
from puppet.io.takes import open_take
from puppet.live.arkit import DEFAULT_MAPPING, CsvError, import_csv, parse_timecode, read_live_link_csv
from puppet.live.mappingfile import load_mapping

ROOT = Path(__file__).resolve().parents[1]
NAMES = ["EyeBlinkLeft", "EyeBlinkRight", "JawOpen", "JawLeft", "MouthSmileLeft", "MouthSmileRight",
         "BrowInnerUp", "CheekPuff", "HeadYaw", "HeadPitch", "HeadRoll"]
OPEN_JAW = 3 - 1       # column of FAP 3 in a (68,) FAP row
HEAD_YAW = 49 - 1


def timecode(frame: int, fps: int = 60, start_s: int = 11 * 3600 + 5 * 60 + 7) -> str:
    s, ff = divmod(frame, fps)
    s += start_s
    return f"{s // 3600:02d}:{s // 60 % 60:02d}:{s % 60:02d}:{ff:02d}.{(frame * 137) % 1000:03d}"


def write_csv(path: Path, rows: int = 60, fps: int = 60) -> Path:
    """A synthetic recording: the jaw opens over the second half, the head turns slightly (0.01 rad)."""
    lines = ["Timecode,BlendShapeCount," + ",".join(NAMES)]
    for i in range(rows):
        jaw = 0.0 if i < rows // 2 else (i - rows // 2) / (rows - rows // 2 - 1)
        values = dict.fromkeys(NAMES, 0.0)
        values.update(JawOpen=jaw, EyeBlinkLeft=0.5 if i == 10 else 0.0, MouthSmileLeft=0.25,
                      HeadYaw=0.01)
        lines.append(f"{timecode(i, fps)},{len(NAMES)}," + ",".join(f"{values[n]:.6f}" for n in NAMES))
    path.write_text("\n".join(lines) + "\n", "utf-8")
    return path


def test_the_shipped_mapping_loads_and_follows_the_schema():
    schema = json.loads((ROOT / "mappings" / "schema.json").read_text())
    errors = [e.message for e in jsonschema.Draft202012Validator(schema).iter_errors(
        yaml.safe_load(DEFAULT_MAPPING.read_text()))]
    assert errors == []
    m = load_mapping(DEFAULT_MAPPING)
    assert m.devices == {"csv": "replay:///dev/null"}
    assert all(c.targets for c in m.channels())
    assert all(c.name.startswith("csv.") for c in m.channels())
    assert not m.pose().fap.any()


def test_timecodes_count_frames_and_sub_frames():
    assert parse_timecode("00:00:01:00.000", 60) == 1_000_000_000
    assert parse_timecode("00:00:00:30", 60) == 500_000_000
    assert parse_timecode("00:00:00:01.500", 60) == 25_000_000
    assert parse_timecode("01:02:03:15", 30) == (3723 * 1_000_000_000) + 500_000_000
    with pytest.raises(ValueError, match="frame 60"):
        parse_timecode("00:00:00:60.000", 60)
    with pytest.raises(ValueError, match="timecode"):
        parse_timecode("12:00:00", 60)


def test_rows_are_read_from_the_first_timecode(tmp_path):
    rows = list(read_live_link_csv(write_csv(tmp_path / "take.csv")))
    assert len(rows) == 60
    assert rows[0][0] == 0
    assert rows[1][0] == pytest.approx(1e9 / 60 + (137 / 1000) * 1e9 / 60, abs=1)
    assert all(b[0] > a[0] for a, b in itertools.pairwise(rows))
    assert set(rows[0][1]) == set(NAMES)            # Timecode and BlendShapeCount are no channels
    assert rows[-1][1]["JawOpen"] == 1.0


def test_midnight_is_crossed(tmp_path):
    path = tmp_path / "night.csv"
    path.write_text("Timecode,JawOpen\n23:59:59:59.000,0\n00:00:00:00.000,1\n")
    assert [t for t, _ in read_live_link_csv(path)] == [0, round(1e9 / 60)]


@pytest.mark.parametrize("text, line, message", [
    ("Timecode,JawOpen\n00:00:00:00.000,0\n00:00:00:xx.000,0\n", 3, "timecode"),
    ("Timecode,JawOpen\n00:00:00:00.000,0\n\n00:00:00:01.000,oops\n", 4, "'JawOpen'.*'oops'"),
    ("Timecode,JawOpen\n00:00:00:00.000,0,1\n", 2, "expected 2 fields"),
    ("Timecode,JawOpen\n00:00:00:05.000,0\n00:00:00:04.000,0\n", 3, "back in time"),
    ("Timecode,JawOpen\n00:00:00:00.000,nan\n", 2, "expected a number"),
    ("Time,JawOpen\n00:00:00:00.000,0\n", 1, "'Timecode'"),
    ("Timecode,JawOpen,JawOpen\n", 1, "twice"),
    ("Timecode,BlendShapeCount\n", 1, "no blendshape"),
    ("", 1, "empty"),
])
def test_bad_files_name_the_file_and_line(tmp_path, text, line, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(CsvError, match=message) as info:
        list(read_live_link_csv(path))
    assert str(info.value).startswith(f"{path}:{line}: ")


def test_import_makes_a_take(tmp_path):
    csv_path = write_csv(tmp_path / "take.csv")
    folder = import_csv(csv_path, tmp_path / "takes")
    assert folder == tmp_path / "takes" / "arkit_001"
    take = open_take(folder)
    assert take.meta["fps"] == 30 and take.meta["frames"] == 30 and take.meta["samples"] == 60
    assert take.meta["devices"] == {"csv": "replay:///dev/null"}
    assert take.meta["source"] == str(csv_path)

    samples = list(take.samples())
    assert len(samples) == 60
    assert [s.t_ns for s in samples] == [t for t, _ in read_live_link_csv(csv_path)]
    assert all(s.device == "csv" and set(s.values) == set(NAMES) for s in samples)

    stream = take.stream()
    assert stream.values.shape == (30, 68) and stream.fps == 30
    jaw = stream.values[:, OPEN_JAW]
    # rows 0-29 (0 .. 0.5 s) closed, then JawOpen rises to 1 at row 59 (about 0.98 s)
    assert not jaw[:15].any()
    assert np.all(np.diff(jaw[15:]) > 0)
    assert jaw[-1] > 700
    assert stream.values[:, 11].min() > 0                   # raise_l_cornerlip: the smile holds
    # head yaw 0.01 rad -> 1000 AU (1e-5 rad), with FAP 49's own sign
    assert stream.values[5, HEAD_YAW] == pytest.approx(0.01 / AU, rel=0.01)


def test_import_at_another_rate_and_a_bad_file_leaves_no_take(tmp_path):
    folder = import_csv(write_csv(tmp_path / "take.csv"), tmp_path / "takes", name="scene", fps=60)
    assert open_take(folder).meta["frames"] == 60
    bad = tmp_path / "bad.csv"
    bad.write_text("Timecode,JawOpen\n00:00:00:00.000,0\n00:00:00:01.000,x\n")
    with pytest.raises(CsvError, match=rf"{bad}:3:"):
        import_csv(bad, tmp_path / "takes", name="bad")
    assert not (tmp_path / "takes" / "bad_001").exists()


def test_a_missing_file_is_a_csv_error(tmp_path):
    with pytest.raises(CsvError, match="cannot read the CSV"):
        list(read_live_link_csv(tmp_path / "nope.csv"))
