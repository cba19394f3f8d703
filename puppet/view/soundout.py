"""A take's sound played out in step with the picture: the player's clock says where to be.

``ClockedSound`` opens a PortAudio output (``sounddevice``) whose callback asks the player for
the take's time at the moment the block it fills will be heard (now plus the output's latency),
and plays the soundtrack from there: silence while paused, a jump when the player seeks, steps
or loops (when the playhead and the sound part by more than ``RESYNC_S``), and otherwise one
continuous stream. With no output device it says so in one line and the take plays silent.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from puppet.io.soundtrack import Soundtrack

RESYNC_S = 0.04


class ClockedSound:
    """The soundtrack played where ``where(t)`` says the take is at ``time.perf_counter()`` time
    t (seconds into the take; None: paused)."""

    def __init__(self, sound: Soundtrack, where: Callable[[float], float | None]) -> None:
        self.sound, self.where = sound, where
        self._cursor: int | None = None   # the next sample to play, when playing on
        self._lock = threading.Lock()
        self._stream = None

    def start(self, note: Callable[[str], None]) -> bool:
        """Open the output and start; False (after ``note`` says why) when there is none."""
        try:
            import sounddevice as sd

            self._stream = sd.OutputStream(samplerate=self.sound.rate, channels=1, dtype="int16",
                                           callback=self._callback, latency="low")
            self._stream.start()
        except (OSError, Exception) as exc:  # noqa: BLE001 -- PortAudio missing, no output, busy
            self._stream = None
            note(f"no sound output ({' '.join(str(exc).split())}): playing without sound")
            return False
        return True

    def fill(self, out: np.ndarray, heard_at: float) -> None:
        """Fill ``out`` (int16 frames) with what should be heard from ``heard_at`` on."""
        t = self.where(heard_at)
        if t is None:
            self._cursor = None
            out[:] = 0
            return
        rate, pcm = self.sound.rate, self.sound.pcm
        due = round(t * rate)
        if self._cursor is None or abs(due - self._cursor) > RESYNC_S * rate:
            self._cursor = due
        start = self._cursor
        out[:] = 0
        part = pcm[max(start, 0):max(start + len(out), 0)]
        offset = max(-start, 0)
        out[offset:offset + len(part)] = part[:len(out) - offset]
        self._cursor = start + len(out)

    def _callback(self, outdata: np.ndarray, frames: int, timing, status) -> None:
        with self._lock:
            self.fill(outdata[:, 0], time.perf_counter() + self._stream.latency)

    def close(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            stream.abort()
            stream.close()
