"""Live Link Face / ARKit blendshape CSV files, read and imported as takes.

Epic's Live Link Face app records a CSV with a header row ::

    Timecode,BlendShapeCount,EyeBlinkLeft,...,JawOpen,...,HeadYaw,HeadPitch,HeadRoll,LeftEyeYaw,...

and one row per captured frame: a timecode ``HH:MM:SS:FF.fff`` (``FF`` the frame at the
recording rate, ``.fff`` a fraction of a frame) and one float per named column. ``BlendShapeCount``
is the number of columns, not a shape, and is dropped. Blendshape weights are 0..1; head and eye
angles are read as radians (``mappings/arkit_csv.yaml`` says how they reach the face).

``read_live_link_csv`` yields ``(t_ns, {name: value})`` with ``t_ns`` counted from the first row;
``import_csv`` feeds each row as a ``Sample(t_ns, "csv", values)`` through a mapping into a take
(``puppet.io.takes``, written by a ``TakeClock`` as a live take is, so ``puppet replay --mapping``
can re-map it): every row in the raw sample log, and the Pose sampled at ``k / fps`` seconds
for every frame time up to the last row. Every problem in a file is a ``CsvError`` naming
``file:line:``.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Iterator
from pathlib import Path

from devices.base import Sample
from puppet.errors import PuppetError
from puppet.io.samplelog import LogEvent
from puppet.io.shipped import shipped_mapping
from puppet.io.takes import TakeRecorder
from puppet.live.mappingfile import load_mapping
from puppet.live.takeclock import TakeClock, default_muscle_faps

DEVICE = "csv"
DEFAULT_MAPPING = shipped_mapping("arkit_csv")
SKIPPED = ("BlendShapeCount",)
DAY_NS = 24 * 3600 * 1_000_000_000

_TIMECODE = re.compile(r"(\d{1,2}):(\d{2}):(\d{2})[:;](\d{1,3})(?:\.(\d{1,9}))?\Z")


class CsvError(PuppetError, ValueError):
    """A CSV that cannot be read; the message starts with ``file:line:``."""


def parse_timecode(text: str, fps: float = 60) -> int:
    """Nanoseconds since midnight of a ``HH:MM:SS:FF[.fff]`` timecode at ``fps`` frames/s.

    ``ValueError`` (without a file or line) for anything else, or a frame number >= ``fps``."""
    m = _TIMECODE.match(text.strip())
    if m is None:
        raise ValueError(f"timecode {text!r}: expected HH:MM:SS:FF or HH:MM:SS:FF.fff")
    h, mi, s, ff = (int(g) for g in m.groups()[:4])
    if mi > 59 or s > 59 or h > 23:
        raise ValueError(f"timecode {text!r}: hours, minutes or seconds out of range")
    if ff >= fps:
        raise ValueError(f"timecode {text!r}: frame {ff} is not below the frame rate {fps:g} "
                         f"(is the file recorded at another rate? pass fps=...)")
    frac = m.group(5) or "0"
    scale = 10 ** len(frac)
    frames_scaled = ff * scale + int(frac)           # frames, times `scale`, exactly
    sub_ns = round(frames_scaled * 1_000_000_000 / (fps * scale))
    return ((h * 60 + mi) * 60 + s) * 1_000_000_000 + sub_ns


def read_live_link_csv(path: str | os.PathLike, fps: float = 60) -> Iterator[tuple[int, dict[str, float]]]:
    """``(t_ns, {name: value})`` per data row of a Live Link Face CSV, ``t_ns`` from the first row.

    ``fps`` is the rate the timecodes' frame field counts at (Live Link Face: 60 or 30). Blank
    lines are skipped; a timecode past midnight continues the day before; a row whose time goes
    backwards, a bad timecode or value, or a row of the wrong length is a ``CsvError`` with
    ``file:line:``."""
    if not (isinstance(fps, (int, float)) and fps > 0 and math.isfinite(fps)):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    file = str(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            yield from _rows(handle, file, fps)
    except OSError as exc:
        raise CsvError(f"{file}: cannot read the CSV: {exc}") from None


def _rows(handle, file: str, fps: float) -> Iterator[tuple[int, dict[str, float]]]:
    reader = csv.reader(handle)
    header, columns = None, []
    first = last = None
    day = 0
    try:
        for row in reader:
            line = reader.line_num
            if not row or all(not cell.strip() for cell in row):
                continue
            if header is None:
                header = [cell.strip() for cell in row]
                columns = _check_header(header, file, line)
                continue
            if len(row) != len(header):
                raise CsvError(f"{file}:{line}: expected {len(header)} fields as in the header, got {len(row)}")
            try:
                t = parse_timecode(row[0], fps) + day
            except ValueError as exc:
                raise CsvError(f"{file}:{line}: {exc}") from None
            if last is not None and t < last:
                if last - t > DAY_NS // 2:           # 23:59:59 -> 00:00:00: the next day
                    day += DAY_NS
                    t += DAY_NS
                else:
                    raise CsvError(f"{file}:{line}: timecode {row[0].strip()!r} goes back in time "
                                   f"from the row before: expected rows in time order")
            values = {}
            for i, name in columns:
                cell = row[i].strip()
                try:
                    v = float(cell)
                except ValueError:
                    v = math.nan
                if not math.isfinite(v):
                    raise CsvError(f"{file}:{line}: column {name!r}: expected a number, got {cell!r}")
                values[name] = v
            if first is None:
                first = t
            last = t
            yield t - first, values
    except csv.Error as exc:
        raise CsvError(f"{file}:{reader.line_num}: not valid CSV ({exc})") from None
    except UnicodeDecodeError as exc:
        raise CsvError(f"{file}: not UTF-8 text ({exc.reason})") from None
    if header is None:
        raise CsvError(f"{file}:1: empty file: expected a header row Timecode,BlendShapeCount,...")


def _check_header(header: list[str], file: str, line: int) -> list[tuple[int, str]]:
    """(column index, name) of the value columns; ``CsvError`` for a header that is not Live Link's."""
    if header[0] != "Timecode":
        raise CsvError(f"{file}:{line}: expected a header row starting with 'Timecode', got {header[0]!r}")
    columns, seen = [], set()
    for i, name in enumerate(header[1:], start=1):
        if not name:
            raise CsvError(f"{file}:{line}: column {i + 1} has no name in the header")
        if name in seen:
            raise CsvError(f"{file}:{line}: column {name!r} appears twice in the header")
        if name == "Timecode":
            raise CsvError(f"{file}:{line}: 'Timecode' must be the first column only")
        seen.add(name)
        if name not in SKIPPED:
            columns.append((i, name))
    if not columns:
        raise CsvError(f"{file}:{line}: the header names no blendshape columns")
    return columns


def import_csv(csv_path: str | os.PathLike, root: str | os.PathLike, name: str = "arkit", fps: int = 30,
               mapping_path: str | os.PathLike = DEFAULT_MAPPING, csv_fps: float = 60) -> Path:
    """Import a Live Link Face CSV as a new take under ``root``; returns the take folder.

    Each row is logged and fed as ``Sample(t_ns, "csv", values)`` through the mapping; frame
    ``k`` (at ``k / fps`` seconds from the first row) is the mapping's Pose after every row up to
    that time, for every frame time up to the last row's. ``csv_fps`` is the rate of the
    timecodes' frame field. The CSV is read through before the take is made, so a bad file
    leaves no half take behind."""
    rows = list(read_live_link_csv(csv_path, csv_fps))
    if not rows:
        raise CsvError(f"{csv_path}: the CSV holds no rows after its header: nothing to import")
    mapping = load_mapping(mapping_path)
    extra = {"source": str(csv_path), "t0_ns": 0, "hold_ns": None, "mapping_state": mapping.snapshot(),
             "wire": {}, "layer": None}
    recorder = TakeRecorder(root, name, fps, mapping_path=mapping_path, devices=mapping.devices, extra=extra)
    clock = TakeClock(mapping, recorder.frame, 0, fps, encode_muscles=default_muscle_faps)
    try:
        for t_ns, values in rows:
            sample = Sample(t_ns, DEVICE, values)
            recorder.sample(sample)
            clock.apply(sample)
        if rows:
            end = LogEvent(rows[-1][0], "frame")
            recorder.event(end)
            clock.apply(end)
    finally:
        recorder.close()
    return recorder.folder
