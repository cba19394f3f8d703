"""The 68 MPEG-4 facial animation parameters (ISO/IEC 14496-2 Annex C) as a table.

The facts live in ``puppet/data/fap_table.csv`` (number, name, unit, uni/bidirectional, positive
direction, group, feature point) and ``fap_coding_params.csv`` (the reference encoder's
quantisation step and the Greta editor's slider range: an editing convention, not a limit, so
nothing clamps a file's values to it; ``puppet.runtime.fapcalibration`` searches it), copied from the
project's reference folder. Directions are in the MPEG-4 face frame: +x the face's own left, +y up, +z
forward.
"""

from __future__ import annotations

import csv
import difflib
import functools
import importlib.resources
import io
from dataclasses import dataclass

import numpy as np

from puppet.errors import PuppetError

N_FAPS = 68
UNITS = {"MNS": "MNS0", "MW": "MW0", "ES": "ES0", "ENS": "ENS0", "IRISD": "IRISD0", "AU": "AU"}
DIRECTIONS = {
    "up": (0.0, 1.0, 0.0), "down": (0.0, -1.0, 0.0),
    "left": (1.0, 0.0, 0.0), "right": (-1.0, 0.0, 0.0),
    "forward": (0.0, 0.0, 1.0),
}


class UnknownFapError(PuppetError, KeyError):
    """A FAP number or name that does not exist; the message suggests the closest names."""

    def __str__(self) -> str:
        return str(self.args[0])


@dataclass(frozen=True)
class Fap:
    """One row of the FAP table."""

    number: int
    name: str
    unit: str | None  # FAPU key of Face.fapu ("MNS0", ..., "AU"); None for FAPs 1 and 2
    bidirectional: bool
    direction: str
    group: int
    feature_points: tuple[str, ...]
    quant_step: int
    low: float | None  # Greta editor's slider range (not a limit), None where the table gives none
    high: float | None
    description: str = ""  # what it moves, as the table says

    @property
    def axis(self) -> np.ndarray | None:
        """Unit vector of the positive direction for translations, else None."""
        d = DIRECTIONS.get(self.direction)
        return None if d is None else np.array(d)


@functools.lru_cache(maxsize=1)
def faps() -> tuple[Fap, ...]:
    """All 68 FAPs, index 0 = FAP 1."""
    table = _rows("fap_table.csv")
    coding = {int(r["number"]): r for r in _rows("fap_coding_params.csv")}
    out = []
    for row in table:
        number = int(row["number"])
        code = coding[number]
        out.append(Fap(
            number=number,
            name=row["name"],
            unit=UNITS.get(row["unit"]),
            bidirectional=row["directionality"] == "B",
            direction=row["positive_direction"],
            group=int(row["group"]),
            feature_points=tuple(p for p in row["feature_point"].split(";") if p != "na"),
            quant_step=int(code["quant_step_ref_encoder"]),
            low=float(code["greta_editor_min"]) if code["greta_editor_min"] else None,
            high=float(code["greta_editor_max"]) if code["greta_editor_max"] else None,
            description=row["description"],
        ))
    if [f.number for f in out] != list(range(1, N_FAPS + 1)):
        raise RuntimeError("fap_table.csv must list FAPs 1..68 in order")
    return tuple(out)


@functools.lru_cache(maxsize=1)
def _by_name() -> dict[str, Fap]:
    return {f.name: f for f in faps()}


def fap(key: int | str) -> Fap:
    """The FAP with this number (1-68, also as a string) or name; a clear error otherwise."""
    if isinstance(key, (int, np.integer)) or (isinstance(key, str) and key.strip().isdigit()):
        number = int(key)
        if 1 <= number <= N_FAPS:
            return faps()[number - 1]
        raise UnknownFapError(f"FAP number {number} does not exist (FAPs are numbered 1 to {N_FAPS})")
    found = _by_name().get(str(key))
    if found is None:
        close = difflib.get_close_matches(str(key), list(_by_name()), n=3, cutoff=0.5)
        hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise UnknownFapError(f"unknown FAP name {key!r}{hint}")
    return found


@functools.lru_cache(maxsize=1)
def clamp_ranges() -> tuple[np.ndarray, np.ndarray]:
    """(low, high) arrays over the 68 FAPs, -inf/+inf where the table gives no range: the Greta
    editor's sliders (a file may go past them; the face's own limits are ``FapEngine.shown``).
    Read-only: every caller shares the cached pair."""
    low = np.array([-np.inf if f.low is None else f.low for f in faps()])
    high = np.array([np.inf if f.high is None else f.high for f in faps()])
    low.setflags(write=False)
    high.setflags(write=False)
    return low, high


def _rows(name: str) -> list[dict[str, str]]:
    text = importlib.resources.files("puppet").joinpath("data", name).read_text("utf-8")
    return list(csv.DictReader(io.StringIO(text)))
