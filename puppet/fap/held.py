"""Held FAPs: what a player shows between the values a FAP stream sends.

A .fap frame transmits only its masked FAPs; the others keep the value they last had (the
decoder's rule in MPEG-4 players), starting from neutral. ``HeldFaps`` applies that rule frame by
frame, so a take of any length plays in constant memory.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from puppet.fap.frame import FapFrame
from puppet.fap.highlevel import expand, limit_fields


@dataclass
class HeldFaps:
    """The FAP state a player holds: values of FAPs 3..68 and the FAP 1/2 fields, masked-in."""

    values: np.ndarray
    viseme: np.ndarray | None = None
    expression: np.ndarray | None = None

    @classmethod
    def neutral(cls) -> HeldFaps:
        return cls(np.zeros(68))

    def update(self, frame: FapFrame) -> HeldFaps:
        """Take this frame's masked values; keep the rest."""
        self.values[frame.mask] = frame.values[frame.mask]
        if frame.mask[0]:
            self.viseme = frame.viseme.copy()
        if frame.mask[1]:
            self.expression = frame.expression.copy()
        return self

    def low_level(self) -> np.ndarray:
        """The held state as 68 low-level FAPs (visemes and expressions expanded)."""
        values = self.values.copy()
        values[:2] = 0
        return expand(values, *limit_fields(self.viseme, self.expression))


def held_low_level(frames: Iterable[FapFrame]) -> Iterator[np.ndarray]:
    """Per frame, the FAP state a player holds, as 68 low-level values (FAP 1 / 2 expanded)."""
    held = HeldFaps.neutral()
    for frame in frames:
        yield held.update(frame).low_level()
