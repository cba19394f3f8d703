"""``audio://``: a microphone (any sound input PortAudio has), through ``sounddevice``.

``audio://`` is the system's default input; ``audio://NAME_OR_INDEX?rate=48000&block=10ms&gate=-45``
picks another (a part of its name, percent-encoded, or its PortAudio index: ``puppet devices``
lists them as URLs). Each block of sound becomes one reading of the voice channels
(``devices.voice``), with the block itself on the Sample (``devices.sound_device``).

PortAudio calls back with each block in its own thread; the callback only stamps and queues it,
so the reader thread does the analysis. A block PortAudio had to drop (``input_overflow``) counts
as an overrun, one that came short (``input_underflow``) as an underrun. A missing or busy input,
or one that stops delivering sound for ``SILENT_S`` (unplugged), is LOST with the reason, and the
device reopens with backoff like every other: PortAudio is asked for its inputs afresh each
time, so an input plugged in later is found. Its twin is the take's sound played through
``wav://`` (``devices.wav_device.SoundTwin``).
"""

from __future__ import annotations

import errno
import queue
import time
from typing import Any
from urllib.parse import quote, unquote

import numpy as np

from devices.base import DeviceError, DeviceLost, Found, Url
from devices.sound_device import SOUND_OPTIONS, SoundDevice, sound_options
from devices.wav_device import SoundTwin

SILENT_S = 1.0
PORTAUDIO_HINT = "the PortAudio library is missing (Debian/Ubuntu: sudo apt-get install libportaudio2)"


def _sounddevice() -> Any:
    """The ``sounddevice`` module; an OSError saying what to install when PortAudio is missing."""
    try:
        import sounddevice
    except OSError:
        raise OSError(PORTAUDIO_HINT) from None
    return sounddevice


class AudioDevice(SoundDevice):
    """A sound input read through PortAudio (see the module docstring)."""

    OPTIONS = SOUND_OPTIONS

    def __init__(self, name: str, which: str = "", *, sd_module: Any = None, **options: Any) -> None:
        super().__init__(name, **options)
        self.which = which
        self._sd = sd_module  # sounddevice, or a stand-in with its interface (devices.simulated_audio)
        self._stream: Any = None
        self._heard: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._heard_ns = 0

    @classmethod
    def from_url(cls, url: Url, name: str, sd_module: Any = None) -> AudioDevice:
        cls.check_options(url)
        return cls(name, unquote(url.target.strip("/")), sd_module=sd_module, **sound_options(url))

    def _input(self, sd: Any) -> int | str | None:
        """The PortAudio input the URL names (None: the default); an OSError when there is none."""
        sd._terminate()   # PortAudio lists its devices once per initialisation: look afresh
        sd._initialize()
        if not self.which:
            if sd.default.device[0] is None or sd.default.device[0] < 0:
                raise OSError(errno.ENODEV, "no sound input on this machine (no default input device)")
            return None
        which = int(self.which) if self.which.isdigit() else self.which
        try:
            info = sd.query_devices(which, "input")
        except (ValueError, sd.PortAudioError) as exc:  # sounddevice: ValueError for a name no input has
            raise OSError(errno.ENODEV, f"no sound input {self.which!r} ({exc})") from None
        if info["max_input_channels"] < 1:
            raise OSError(errno.ENODEV, f"{info['name']!r} has no input channels")
        return which

    def _open(self) -> None:
        sd = self._sd or _sounddevice()
        which = self._input(sd)
        self._heard = queue.SimpleQueue()
        try:
            self._stream = sd.InputStream(device=which, channels=1, samplerate=self.rate, blocksize=self.block,
                                          dtype="int16", callback=self._callback, latency="low")
            self._stream.start()
        except sd.PortAudioError as exc:
            self._stream = None
            raise OSError(f"the input would not open ({exc}): busy, or it cannot give {self.rate} Hz") from None
        self._heard_ns = time.monotonic_ns()

    def _callback(self, indata: np.ndarray, frames: int, timing: Any, status: Any) -> None:
        now = time.monotonic_ns()
        if status.input_overflow:
            self.counters.overruns += 1
        if status.input_underflow:
            self.counters.underruns += 1
        latency = self._stream.latency if self._stream is not None else 0.0
        start = now - int((frames / self.rate + latency) * 1e9)
        self._heard.put((indata[:, 0].copy(), start))

    def _blocks(self) -> list[tuple[np.ndarray, int]]:
        try:
            blocks = [self._heard.get(timeout=0.1)]
        except queue.Empty:
            if not self._stream.active or time.monotonic_ns() - self._heard_ns > SILENT_S * 1e9:
                raise DeviceLost(f"no sound from the input for {SILENT_S:g} s (unplugged?)") from None
            return []
        while True:
            try:
                blocks.append(self._heard.get_nowait())
            except queue.Empty:
                break
        self._heard_ns = time.monotonic_ns()
        return blocks

    def _close(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            try:
                stream.abort()
                stream.close()
            except Exception:  # noqa: BLE001 -- an input that vanished may refuse to close
                pass


def discover(sd_module: Any = None) -> list[Found]:
    """The sound inputs PortAudio has, as ``audio://NAME`` URLs."""
    try:
        sd = sd_module or _sounddevice()
    except OSError as exc:
        raise DeviceError(str(exc)) from None
    found = []
    for index, info in enumerate(sd.query_devices()):
        if info["max_input_channels"] > 0:
            host = sd.query_hostapis(info["hostapi"])["name"]
            found.append(Found("audio", f"audio://{quote(info['name'], safe='')}",
                               f"input {index}: {info['max_input_channels']} ch, "
                               f"{info['default_samplerate']:.0f} Hz ({host})"))
    return found


DEVICE, TWIN = AudioDevice, SoundTwin
