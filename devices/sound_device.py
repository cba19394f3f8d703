"""What every audio device has in common: blocks of sound in, one analysed reading per block out.

A ``SoundDevice`` is a ``Device`` whose backend hands over blocks of 16-bit mono PCM
(``_blocks``) instead of readings; this class runs each block through its ``devices.voice.Voice``
in the reader thread (off the live loop) and queues a Sample with the voice's channels and the
block itself (``Sample.sound``), so that a take can keep the sound beside what it made. Its URL
options, shared by ``audio://`` and ``wav://``: ``rate`` (Hz, default 48000), ``block`` (``10ms``
or a frame count, default 10 ms), ``gate`` (dBFS where the noise gate opens, default -45).
``level_db`` is the newest block's level, for the cockpit's meter.
"""

from __future__ import annotations

import re
import time
from abc import abstractmethod
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from devices.base import Device, DeviceError, Sample, Sound, Url
from devices.voice import GATE_DB, Voice

RATE = 48000
BLOCK_S = 0.010
SOUND_OPTIONS = frozenset({"rate", "block", "gate"})


def sound_options(url: Url) -> dict[str, Any]:
    """``rate``, ``block`` (frames) and ``gate`` (dBFS) from a sound URL's options, checked."""
    options = url.options
    try:
        rate = int(options.get("rate", RATE))
    except ValueError:
        raise DeviceError(f"{url.scheme}://{url.target}: rate={options['rate']!r}: expected a whole number "
                          "of Hz") from None
    if not 8000 <= rate <= 192000:
        raise DeviceError(f"{url.scheme}://{url.target}: rate={rate}: expected 8000 to 192000 Hz")
    block = _block_frames(options.get("block", "10ms"), rate, url)
    try:
        gate = float(options.get("gate", GATE_DB))
    except ValueError:
        raise DeviceError(f"{url.scheme}://{url.target}: gate={options['gate']!r}: expected dBFS, e.g. -45") from None
    if not -120.0 <= gate <= 0.0:
        raise DeviceError(f"{url.scheme}://{url.target}: gate={gate:g}: expected -120 to 0 dBFS")
    return {"rate": rate, "block": block, "gate": gate}


def _block_frames(text: str, rate: int, url: Url) -> int:
    """A block given as ``10ms`` or as frames, in frames (2.5 to 50 ms)."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*(ms)?\s*", text)
    if not match:
        raise DeviceError(f"{url.scheme}://{url.target}: block={text!r}: expected milliseconds (10ms) or frames (480)")
    frames = round(float(match.group(1)) * rate / 1000) if match.group(2) else int(float(match.group(1)))
    if not 0.0025 * rate <= frames <= 0.05 * rate:
        raise DeviceError(f"{url.scheme}://{url.target}: block={text}: expected 2.5 to 50 ms of sound "
                          f"({int(0.0025 * rate)} to {int(0.05 * rate)} frames at {rate} Hz)")
    return frames


class SoundDevice(Device):
    """An audio input whose blocks are analysed into voice channels (see the module docstring)."""

    def __init__(self, name: str, rate: int = RATE, block: int = round(RATE * BLOCK_S),
                 gate: float = GATE_DB) -> None:
        super().__init__(name)
        self.rate, self.block, self.gate = rate, block, gate
        self.voice = Voice(rate, gate)
        self.level_db = -120.0

    @abstractmethod
    def _blocks(self) -> list[tuple[np.ndarray, int]]:
        """Wait briefly (well under a second) for sound; return the blocks that came, each as
        (``block`` frames of 16-bit mono PCM, ``time.monotonic_ns()`` of its first frame)."""

    def _read(self) -> Iterable[Mapping[str, float]]:
        raise NotImplementedError("a sound device queues its Samples in _pump")

    def wire_info(self) -> dict[str, Any]:
        """The analysis's settings: a take's replay through ``wav://`` analyses its sound with them."""
        return {"rate": self.rate, "block": self.block, "gate": self.gate}

    def _reading(self, pcm: np.ndarray) -> tuple[dict[str, Any], dict[str, float]]:
        """The analysis's state before ``pcm``, and the reading of it."""
        state = self.voice.state()
        return state, self.voice(pcm)

    def _pump(self) -> None:
        while not self._stop.is_set():
            for pcm, start_ns in self._blocks():
                state, values = self._reading(pcm)
                self.level_db = values["db"]
                sound = Sound(pcm, self.rate, start_ns, state)
                self._push(Sample(time.monotonic_ns(), self.name, values, sound))
