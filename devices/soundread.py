"""Sound files in: any format libsndfile reads, as 16-bit mono PCM at the rate asked for.

``read_sound(path, rate)`` is what ``wav://`` plays and what a take's sound is read back with. It
trusts nothing in the file: a file that is missing, empty, not a sound file, claims more sound
than ``MAX_SECONDS`` or more than its bytes can hold, or breaks off mid-way is a ``SoundFileError``
naming the file and what was wrong, in one line. Channels are mixed down to mono; another
sample rate is resampled (polyphase, ``scipy.signal.resample_poly``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from devices.base import DeviceError

MAX_SECONDS = 4 * 3600  # a four-hour recording, mono 48 kHz: 1.3 GB as float32 while it is read


class SoundFileError(DeviceError, ValueError):
    """A sound file that cannot be read as sound (names the file and what is wrong)."""


def read_sound(path: str | os.PathLike[str], rate: int | None = None) -> tuple[np.ndarray, int]:
    """The file's sound as 16-bit mono PCM, and its rate: ``rate`` when given (resampled to it),
    else the file's own."""
    import soundfile

    path = Path(path)
    if not path.is_file():
        raise SoundFileError(f"{path}: no such sound file")
    size = path.stat().st_size
    if size == 0:
        raise SoundFileError(f"{path}: the file is empty (0 bytes), expected sound")
    try:
        with soundfile.SoundFile(str(path)) as file:
            _check_claim(path, file, size)
            data = file.read(dtype="float32", always_2d=True)
            claimed, own_rate = file.frames, file.samplerate
    except soundfile.LibsndfileError as exc:
        raise SoundFileError(f"{path}: not a sound file libsndfile can read ({_reason(exc)})") from None
    except (RuntimeError, TypeError) as exc:
        raise SoundFileError(f"{path}: not a sound file libsndfile can read ({exc})") from None
    if len(data) == 0:
        raise SoundFileError(f"{path}: the file holds no sound (0 frames)")
    if claimed > 0 and len(data) < claimed:
        raise SoundFileError(f"{path}: truncated: its header says {claimed:,} frames, the file holds {len(data):,}")
    mono = data.mean(axis=1) if data.shape[1] > 1 else data[:, 0]
    target = own_rate if rate is None else int(rate)
    if target != own_rate:
        mono = _resample(mono, own_rate, target)
    return to_pcm(mono), target


def to_pcm(sound: np.ndarray) -> np.ndarray:
    """Float sound (-1..1) as 16-bit PCM, clipped; on libsndfile's scale (full scale 32768), so
    16-bit sound read as floats comes back exactly."""
    return np.clip(np.round(np.asarray(sound, dtype=np.float64) * 32768.0), -32768, 32767).astype(np.int16)


def _check_claim(path: Path, file: Any, size: int) -> None:
    """Refuse a file that claims more sound than is sane, or (a WAV) more than its bytes hold:
    libsndfile itself counts what is there and would read a cut file without a word."""
    seconds = file.frames / max(file.samplerate, 1)
    claimed = _wav_data_bytes(path) if file.format in ("WAV", "WAVEX") else None
    if claimed is not None and file.channels and file.samplerate:
        seconds = max(seconds, claimed / (_bytes_per_frame(file) * file.samplerate))
    if seconds > MAX_SECONDS:
        raise SoundFileError(f"{path}: claims {seconds / 3600:.1f} hours of sound, more than the "
                             f"{MAX_SECONDS // 3600} hours read at once")
    if claimed is not None and claimed > size:
        raise SoundFileError(f"{path}: truncated: its header claims {claimed:,} bytes of sound in a file of {size:,}")


def _wav_data_bytes(path: Path) -> int | None:
    """The size a RIFF WAV's ``data`` chunk declares (None: not found, or 0 / 0xFFFFFFFF, the
    "unknown length" of a stream that was never finished)."""
    with open(path, "rb") as file:
        head = file.read(12)
        if len(head) < 12 or head[:4] not in (b"RIFF", b"RF64") or head[8:12] != b"WAVE":
            return None
        for _ in range(64):
            chunk = file.read(8)
            if len(chunk) < 8:
                return None
            kind, length = chunk[:4], int.from_bytes(chunk[4:], "little")
            if kind == b"data":
                return None if length in (0, 0xFFFFFFFF) else length
            file.seek(length + (length & 1), 1)
    return None


def _bytes_per_frame(file: Any) -> int:
    bits = {"PCM_S8": 8, "PCM_U8": 8, "PCM_16": 16, "PCM_24": 24, "PCM_32": 32, "FLOAT": 32, "DOUBLE": 64,
            "ULAW": 8, "ALAW": 8}.get(file.subtype, 16)
    return max(1, int(file.channels) * bits // 8)


def _resample(sound: np.ndarray, rate: int, target: int) -> np.ndarray:
    from scipy.signal import resample_poly

    common = math.gcd(rate, target)
    resampled: np.ndarray = resample_poly(sound.astype(np.float64), target // common, rate // common)
    return resampled


def _reason(exc: Exception) -> str:
    text = getattr(exc, "error_string", None) or str(exc)
    return " ".join(text.split()).rstrip(".")
