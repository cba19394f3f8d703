"""``wav://``: a sound file played as a microphone, at real-time pace, through the same analysis.

``wav://speech.wav?speed=1&loop=0&rate=48000&block=10ms&gate=-45&mode=live`` reads any format
libsndfile reads (WAV, FLAC, Ogg, AIFF ...; ``devices.soundread``), mixed to mono and resampled to
``rate``, and hands it over block by block when each block would have been heard: block k at
``start + (k + 1) * block / speed`` (``speed=0``: as fast as the reader takes them). A reader
that falls more than a block behind catches up (each late block counts as an underrun). At the
end it stops, or starts over with ``loop=1``. ``mode=offline`` gives each block the readings of
``devices.voice.offline`` (look-ahead over the whole file) instead of the causal ones; with
``script=the words`` (and ``language``, espeak-ng's, default en-us) they follow the script's
phones aligned to the sound (``devices.voicescript``).

A file that is missing or unreadable makes the device LOST with the reason (the face holds), and
it is tried again with backoff, as an unplugged controller is.

``SoundTwin`` is the wire of every sound device (``audio://`` too): a take keeps the sound its
device heard (``take.wav``) and the analysis's state before the first block, so replaying the take
through its devices plays that sound, block by block, through a ``WavDevice`` into the same
readings, bit for bit.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from devices.base import DeviceError, Sound, Url
from devices.sound_device import SOUND_OPTIONS, SoundDevice, sound_options
from devices.soundread import read_sound
from devices.twin import Twin
from devices.voice import offline
from devices.voicescript import script_phones

MODES = ("live", "offline")


class WavDevice(SoundDevice):
    """A sound file played back as a sound input (see the module docstring)."""

    OPTIONS = SOUND_OPTIONS | {"speed", "loop", "mode", "script", "language"}

    def __init__(self, name: str, path: str | Path, *, speed: float = 1.0, loop: bool = False,
                 mode: str = "live", stepped: bool = False, script: str | None = None,
                 language: str = "en-us", **options: Any) -> None:
        super().__init__(name, **options)
        if speed < 0 or mode not in MODES:
            raise DeviceError(f"wav://{path}: expected speed >= 0 and mode in {MODES}, got {speed:g} and {mode!r}")
        if script is not None and mode != "offline":
            raise DeviceError(f"wav://{path}: a script is aligned with look-ahead: give mode=offline with it")
        self.path, self.speed, self.loop, self.mode = Path(path), speed, loop, mode
        self.script, self.language = script, language
        self.finished = False
        self.block_index = 0          # the next block to hand over
        self._pcm: np.ndarray | None = None
        self._offline: list[dict[str, float]] | None = None
        self._start_ns = 0
        self._steps = threading.Semaphore(0) if stepped else None

    @classmethod
    def from_url(cls, url: Url, name: str) -> WavDevice:
        cls.check_options(url)
        options = url.options
        try:
            speed = float(options.get("speed", 1.0))
        except ValueError:
            raise DeviceError(f"wav://{url.target}: speed={options['speed']!r}: expected a number") from None
        if options.get("loop", "0") not in ("0", "1"):
            raise DeviceError(f"wav://{url.target}: loop={options['loop']!r}: expected 0 or 1")
        if not url.target:
            raise DeviceError("wav:// needs a file: wav://speech.wav or wav:///absolute/path.wav")
        return cls(name, url.target, speed=speed, loop=options.get("loop") == "1", mode=options.get("mode", "live"),
                   script=options.get("script"), language=options.get("language", "en-us"), **sound_options(url))

    @property
    def blocks(self) -> int:
        """How many blocks the file makes (0 before it is read)."""
        return 0 if self._pcm is None else len(self._pcm) // self.block

    def load(self) -> None:
        """Read the file (once): whole blocks of it, and in offline mode their readings."""
        if self._pcm is not None:
            return
        pcm, _ = read_sound(self.path, self.rate)
        whole = -(-len(pcm) // self.block) * self.block
        self._pcm = np.concatenate([pcm, np.zeros(whole - len(pcm), np.int16)])
        if self.mode == "offline":
            words = None if self.script is None else script_phones(self.script, self.language)
            self._offline = offline(self._split(), self.rate, self.gate, words)

    def _split(self) -> list[np.ndarray]:
        pcm: np.ndarray = self._pcm  # type: ignore[assignment]  # loaded
        return [pcm[k * self.block:(k + 1) * self.block] for k in range(self.blocks)]

    def readings(self) -> Iterator[tuple[Sound, dict[str, float]]]:
        """Every block from here to the end, unpaced and without the reader thread, as
        ``(Sound, reading)`` with ``start_ns`` counted from the file's start: what an offline
        pass (``puppet lipsync``) records as if the file had been heard live."""
        self.load()
        while self.block_index < self.blocks:
            pcm, start_ns = self._next(round(self.block_index * self.block * 1e9 / self.rate))
            state, values = self._reading(pcm)
            yield Sound(pcm, self.rate, start_ns, state), values

    def step(self) -> None:
        """Hand over the next block now (a stepped device, as a twin drives it)."""
        self._steps.release()  # type: ignore[union-attr]  # a stepped device has steps

    def _open(self) -> None:
        self.load()
        self._start_ns = time.monotonic_ns() - self._played_ns(self.block_index * self.block / self.rate)

    def _blocks(self) -> list[tuple[np.ndarray, int]]:
        if self.block_index >= self.blocks and self.loop:
            self.block_index = 0
            self._start_ns += self._played_ns(self.blocks * self.block / self.rate)
        if self.block_index >= self.blocks:
            self.finished = True
            self._stop.wait(0.02)
            return []
        if self._steps is not None:
            return [self._next(time.monotonic_ns())] if self._steps.acquire(timeout=0.1) else []
        if self.speed == 0:
            return [self._next(time.monotonic_ns())]
        due = self._due(self.block_index + 1)
        wait = (due - time.monotonic_ns()) / 1e9
        if wait > 0:
            self._stop.wait(min(wait, 0.1))
            if time.monotonic_ns() < due:
                return []
        out = [self._next(self._due(self.block_index))]
        while self.block_index < self.blocks and self._due(self.block_index + 1) <= time.monotonic_ns():
            self.counters.underruns += 1
            out.append(self._next(self._due(self.block_index)))
        return out

    def heard_at(self, seconds: float) -> int:
        """When the sound ``seconds`` into the file is heard (``time.monotonic_ns()``), once open."""
        return self._start_ns + self._played_ns(seconds)

    def _due(self, k: int) -> int:
        """When block k's first frame is heard (block k - 1 is complete then)."""
        return self.heard_at(k * self.block / self.rate)

    def _played_ns(self, seconds: float) -> int:
        """How long ``seconds`` of the file take to play at its speed (as at 1 when unpaced)."""
        return int(seconds * 1e9 / (self.speed or 1))

    def _next(self, start_ns: int) -> tuple[np.ndarray, int]:
        k = self.block_index
        self.block_index += 1
        return self._pcm[k * self.block:(k + 1) * self.block], start_ns  # type: ignore[index]  # loaded

    def _reading(self, pcm: np.ndarray) -> tuple[dict[str, Any], dict[str, float]]:
        if self._offline is None:
            return super()._reading(pcm)
        k = self.block_index - 1
        return {"offline_block": k}, self._offline[k]

    def _close(self) -> None:
        pass


class SoundTwin(Twin):
    """A sound device's wire: the take's recorded sound played, block by block, through a
    stepped ``WavDevice`` with the device's analysis settings and the state it had before the
    take's first block (``wire_info``: ``rate``, ``block``, ``gate`` from the device;
    ``sound_file`` and ``sound_state`` from the take)."""
    device: WavDevice  # the adapter this twin feeds

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> SoundTwin:
        parsed = Url.parse(url)
        if "sound_file" not in wire_info:
            raise DeviceError(f"{name}: the take kept no sound for {url!r}, so it cannot be replayed through it")
        options = {key: wire_info[key] for key in ("rate", "block", "gate") if key in wire_info}
        state = wire_info.get("sound_state") or {}
        mode = parsed.options.get("mode", "live") if parsed.scheme == "wav" else "live"
        source = wire_info["sound_file"]
        start = int(state.get("offline_block", 0))
        if mode == "offline" and start > 0:
            source = parsed.target   # the look-ahead needs the file from its start
        script = parsed.options.get("script") if mode == "offline" else None
        device = WavDevice(name, source, speed=0, mode=mode, stepped=True, script=script,
                           language=parsed.options.get("language", "en-us"), **options)
        try:
            device.load()
            device.block_index = start if source == parsed.target else 0
            if mode == "live" and state:
                device.voice.restore(state)
        except (KeyError, TypeError, ValueError) as exc:
            raise DeviceError(f"{name}: the take's sound cannot be replayed through wav://: {exc}") from None
        return cls(device, url)

    def _put(self, values: Mapping[str, float]) -> int:
        self.device.step()
        return 1


DEVICE, TWIN = WavDevice, SoundTwin
