"""A fake ``sounddevice`` module for tests and demos: a microphone that plays a recording.

These machines have no sound card, so ``audio://``'s own code (its callback, queue, unplug
detection and reopening) is exercised against ``FakeSoundDevice``, which stands where the
``sounddevice`` module stands with the parts ``devices.audio_device`` uses and the same behaviour
where it matters:

- ``query_devices()`` lists the plugged microphones (a ``DeviceList`` of dicts: ``name``,
  ``max_input_channels``, ``default_samplerate``, ``hostapi``); ``query_devices(which, "input")``
  finds one by index or part of its name, else raises ``ValueError`` as sounddevice does;
  ``default.device`` is (input, output), -1 with none plugged;
- ``InputStream(device=, channels=, samplerate=, blocksize=, dtype="int16", callback=, latency=)``
  raises ``PortAudioError`` when the microphone is not plugged in; started, it calls ``callback
  (indata, frames, time, status)`` from a thread of its own once a block's worth of time has
  passed, with (blocksize, 1) int16 frames of the recording (looping), and ``status`` flags;
- ``unplug()`` on a ``FakeMicrophone`` stops its callbacks (the stream goes inactive, as PortAudio's
  does when the device vanishes) and hides it from ``query_devices``; ``replug()`` brings it back.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np


class PortAudioError(Exception):
    """What sounddevice raises when PortAudio fails (a device that is not there)."""


@dataclass
class CallbackFlags:
    input_overflow: bool = False
    input_underflow: bool = False


class FakeMicrophone:
    """A microphone: its name, rate and the recording it "hears", and its plug."""

    def __init__(self, name: str, sound: np.ndarray, rate: int = 48000) -> None:
        self.name, self.rate = name, rate
        self.sound = np.asarray(sound, dtype=np.int16)
        self.plugged = True
        self.position = 0

    def unplug(self) -> None:
        self.plugged = False

    def replug(self) -> None:
        self.plugged = True

    def take(self, frames: int) -> np.ndarray:
        """The next ``frames`` of the recording (looping)."""
        index = (self.position + np.arange(frames)) % len(self.sound)
        self.position = int(index[-1]) + 1
        return self.sound[index]


class FakeSoundDevice:
    """The fake module: ``FakeSoundDevice(mic, ...)``, used where ``sounddevice`` would be."""

    PortAudioError = PortAudioError

    def __init__(self, *microphones: FakeMicrophone) -> None:
        self.microphones = list(microphones)
        self.default = _Default(self)

    def _plugged(self) -> list[FakeMicrophone]:
        return [mic for mic in self.microphones if mic.plugged]

    def query_devices(self, which: int | str | None = None, kind: str | None = None) -> Any:
        plugged = self._plugged()
        infos = [{"name": m.name, "max_input_channels": 1, "default_samplerate": float(m.rate), "hostapi": 0}
                 for m in plugged]
        if which is None:
            return infos
        found = self._find(which)
        return infos[plugged.index(found)]

    def query_hostapis(self, index: int) -> dict[str, Any]:
        return {"name": "Fake"}

    def _find(self, which: int | str | None) -> FakeMicrophone:
        plugged = self._plugged()
        if which is None:
            if not plugged:
                raise PortAudioError("Error querying device -1")
            return plugged[0]
        if isinstance(which, int):
            if not 0 <= which < len(plugged):
                raise PortAudioError(f"Error querying device {which}")
            return plugged[which]
        matches = [m for m in plugged if str(which).lower() in m.name.lower()]
        if not matches:
            raise ValueError(f"No input device matching {which!r}")
        return matches[0]

    def InputStream(self, *, device: int | str | None = None, channels: int = 1, samplerate: float = 48000,
                    blocksize: int = 480, dtype: str = "int16", callback: Any = None,
                    latency: Any = None) -> FakeInputStream:
        return FakeInputStream(self._find(device), int(samplerate), int(blocksize), callback)

    def _terminate(self) -> None:
        pass

    def _initialize(self) -> None:
        pass


class _Default:
    def __init__(self, module: FakeSoundDevice) -> None:
        self._module = module

    @property
    def device(self) -> tuple[int, int]:
        return (0 if self._module._plugged() else -1, -1)


class FakeInputStream:
    """A started stream calls back with a block each block's time, until stopped or unplugged."""

    latency = 0.005

    def __init__(self, mic: FakeMicrophone, rate: int, block: int, callback: Any) -> None:
        self.mic, self.rate, self.block, self.callback = mic, rate, block, callback
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def active(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f"fake stream {self.mic.name}", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        start, k = time.monotonic(), 0
        while not self._stop.is_set() and self.mic.plugged:
            k += 1
            wait = start + k * self.block / self.rate - time.monotonic()
            if wait > 0:
                self._stop.wait(wait)
            if self._stop.is_set() or not self.mic.plugged:
                return
            self.callback(self.mic.take(self.block).reshape(-1, 1), self.block, None, CallbackFlags())

    def abort(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)

    def close(self) -> None:
        self.abort()
