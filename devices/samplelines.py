"""Samples as JSON lines: the format of raw sample logs, read and written exactly.

A line is ``{"t_ns": 123456789, "device": "box", "values": {"ch0": 512.0, "ch1": 300.0}}``:
the Sample exactly (JSON keeps floats to the last bit with ``repr``), one line each, so a killed
writer leaves every complete line readable (a last, partial line is skipped with a warning). The
first line may be a header ``{"facepuppet_samples": 1}``. A take's log (``puppet.io.samplelog``)
puts its events between the Samples as lines with an ``"event"`` key; ``read_samples`` skips them.
Every line is bounded: one longer than ``MAX_LINE`` characters is refused unread.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterator

from devices.base import DeviceError, Sample

MAX_LINE = 1 << 20  # characters: a sample of 52 ARKit channels is about 2,000
HEADER = {"facepuppet_samples": 1}


class SampleLogError(DeviceError, ValueError):
    """A sample log line that is not a Sample or an event (names the file and line)."""


def sample_line(sample: Sample) -> str:
    """One Sample as its JSON line (without the newline)."""
    return json.dumps({"t_ns": sample.t_ns, "device": sample.device, "values": dict(sample.values)})


def read_records(path: str | os.PathLike[str]) -> Iterator[tuple[str, object]]:
    """(``file:line``, the line's JSON value) for every line after the header, streamed; a line
    that is not JSON names the file and line (a partial last one warns and ends the log)."""
    with open(path, encoding="utf-8") as file:
        number, text = 0, file.readline(MAX_LINE + 1)
        while text:
            number += 1
            if len(text) > MAX_LINE:
                raise SampleLogError(f"{path}:{number}: a line of more than {MAX_LINE:,} characters, "
                                     "expected one JSON sample")
            following = file.readline(MAX_LINE + 1)
            try:
                data = json.loads(text)
            except (json.JSONDecodeError, RecursionError):
                if not following and not text.endswith("\n"):
                    warnings.warn(f"{path}:{number}: the last line is incomplete (the recorder stopped "
                                  "mid-line); skipped", stacklevel=3)
                    return
                raise SampleLogError(f"{path}:{number}: expected a JSON sample, found {text[:60]!r}") from None
            if data != HEADER:
                yield f"{path}:{number}", data
            text = following


def is_event(data: object) -> bool:
    """Whether a record is an event line rather than a Sample."""
    return isinstance(data, dict) and "event" in data


def sample_from(data: object, where: str) -> Sample:
    """The Sample a record holds; anything else names ``where`` and what was found."""
    if not (isinstance(data, dict) and isinstance(data.get("t_ns"), int) and isinstance(data.get("device"), str)
            and isinstance(data.get("values"), dict)):
        raise SampleLogError(f"{where}: expected {{\"t_ns\": int, \"device\": str, \"values\": {{...}}}}, "
                             f"found {data!r:.80}")
    values = data["values"]
    try:
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values.values()):
            return Sample(data["t_ns"], data["device"], {str(k): float(v) for k, v in values.items()})
    except OverflowError:
        pass
    raise SampleLogError(f"{where}: expected numbers as values, found {values!r:.80}")


def read_samples(path: str | os.PathLike[str]) -> Iterator[Sample]:
    """The Samples of a log, streamed (event lines skipped)."""
    return (sample_from(data, where) for where, data in read_records(path) if not is_event(data))
