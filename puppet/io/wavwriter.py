"""A take's sound on disk: a WAV file that stays readable however the recorder stops.

``WavWriter`` writes 16-bit mono PCM. After every block it rewrites the header's two sizes (the
RIFF chunk and the data chunk) to what is on disk, as ``FapWriter`` keeps a .fap's frame count,
so a recorder killed mid-take leaves a WAV that any player reads up to the last block written
(a kill between a block and its sizes loses that one block, 10 ms).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

HEADER_BYTES = 44


class WavWriter:
    """Appends blocks of 16-bit mono PCM to a WAV file, its header true after every block."""

    def __init__(self, path: str | os.PathLike[str], rate: int) -> None:
        self.path, self.rate = Path(path), int(rate)
        self.frames = 0
        self._file = open(self.path, "wb")
        self._file.write(self._header())
        self._file.flush()

    def write(self, pcm: np.ndarray) -> None:
        """Append one block, then make the header say so."""
        data = np.asarray(pcm, dtype="<i2").tobytes()
        self._file.seek(HEADER_BYTES + 2 * self.frames)
        self._file.write(data)
        self._file.flush()
        self.frames += len(data) // 2
        self._file.seek(0)
        self._file.write(self._header())
        self._file.flush()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> WavWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _header(self) -> bytes:
        data = 2 * self.frames
        return (b"RIFF" + struct.pack("<I", 36 + data) + b"WAVE"
                + b"fmt " + struct.pack("<IHHIIHH", 16, 1, 1, self.rate, 2 * self.rate, 2, 16)
                + b"data" + struct.pack("<I", data))
