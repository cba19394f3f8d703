"""A take's sound as a soundtrack: the first audio device's WAV, lined up with the .fap's frames.

Frame k of a take's .fap shows the pose at ``t0_ns + k / fps`` (``take.json``); the WAV's first
frame was heard at ``first_ns`` on the same clock. ``soundtrack`` pads or trims the sound so that
its sample 0 falls on frame 0 (to the nearest sample: within 0.01 ms at 48 kHz), which is what a
video and a player need. A take without sound has no soundtrack; a damaged or missing WAV is
warned about, naming the file, and the take goes on silent.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from devices.soundread import SoundFileError, read_sound
from puppet.io.takes import FAP_NAME, META_NAME, TakeError, open_take


@dataclass(frozen=True)
class Soundtrack:
    """16-bit mono PCM at ``rate`` whose sample 0 is heard with the take's frame 0."""

    pcm: np.ndarray
    rate: int
    source: Path

    @property
    def seconds(self) -> float:
        return len(self.pcm) / self.rate


def soundtrack(take: str | os.PathLike[str]) -> Soundtrack | None:
    """The sound of the take at ``take`` (its folder, or the take.fap in it), aligned to frame 0;
    None for a take without sound (a bare .fap, a take no microphone was recorded in)."""
    path = Path(take)
    folder = path if path.is_dir() else path.parent if path.name == FAP_NAME else None
    if folder is None or not (folder / META_NAME).is_file():
        return None
    try:
        opened = open_take(folder)
    except TakeError:
        return None
    sounds, t0 = opened.sounds(), opened.meta.get("t0_ns")
    if not sounds or t0 is None:
        return None
    sound = sounds[0]
    try:
        pcm, rate = read_sound(sound.path)
    except SoundFileError as exc:
        warnings.warn(f"{exc}; the take goes on without sound", stacklevel=2)
        return None
    if rate != sound.rate:
        warnings.warn(f"{sound.path}: {rate} Hz where take.json says {sound.rate}; the take goes on without sound",
                      stacklevel=2)
        return None
    return Soundtrack(_aligned(pcm, rate, sound.first_ns - t0), rate, sound.path)


def _aligned(pcm: np.ndarray, rate: int, lead_ns: int) -> np.ndarray:
    """``pcm`` whose first sample comes ``lead_ns`` after frame 0, moved so that it comes at it."""
    shift = round(lead_ns * rate / 1e9)
    if shift >= 0:
        return np.concatenate([np.zeros(shift, np.int16), pcm])
    return pcm[-shift:]
