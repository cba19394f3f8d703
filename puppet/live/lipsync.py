"""``puppet lipsync``: a recording of speech made into a take, the mouth following the voice.

``lipsync(sound, folder)`` plays the file through a ``wav://`` device in its offline mode (the
analysis looks ahead over the whole recording, ``devices.voice.offline``: lips close before a p
is heard and open before the vowel) and records what a mapping (``voice.yaml`` unless another is
given) makes of it, exactly as a live session records a take: ``take.fap``, ``take.wav``, the raw
log and ``take.json``, on a clock that starts at 0 with the sound. So the take renders and plays
with its sound, replays through its device (``puppet replay --through-devices``) into the same
frames, and exports like any other. The mapping's other devices stay at rest.

``script`` gives the words said: espeak-ng reads them into phones, which are aligned to the
sound (``devices.voicescript``), so the mouth makes each phone's shape (an m's pressed lips, an
oo's pucker) when the voice says it.

``over=TAKE`` lays the mouth over an earlier take, as a layered pass does (``takeclock.Layer``):
the mouth's FAPs (jaw, lips, tongue, cheeks' puff) and the viseme come from the voice, the rest
of each frame from that take, which plays on to its own end if it is the longer.
"""

from __future__ import annotations

import os
from pathlib import Path
from urllib.parse import quote, urlencode

from devices.base import Sample, Url
from devices.sound_device import sound_options
from devices.wav_device import WavDevice
from puppet.fap.table import faps
from puppet.io.fapfile import iter_fap
from puppet.io.samplelog import LogEvent
from puppet.io.shipped import mapping_path
from puppet.io.takes import TakeError, TakeRecorder, take_fap
from puppet.live.mappingfile import load_mapping
from puppet.live.takeclock import Layer, TakeClock, default_muscle_faps

MOUTH_GROUPS = (2, 6, 8)
"""FAP groups a voice lays over a take: jaw, chin and inner lips; tongue; outer lips."""


def lipsync(sound: str | os.PathLike, folder: str | os.PathLike, *, mapping: str | os.PathLike | None = None,
            over: str | os.PathLike | None = None, fps: int = 30, lookahead: bool = True,
            script: str | None = None, language: str = "en-us") -> Path:
    """Record the take of ``sound`` into ``folder`` (new or empty); returns the folder. Without
    ``lookahead`` the analysis is the live one: the take a microphone would have given. A
    ``script`` (the words said, in espeak-ng's ``language``) is aligned to the sound and shapes
    the mouth phone by phone."""
    if script is not None and not lookahead:
        raise TakeError("a script is aligned with look-ahead: it cannot be used with the live analysis")
    mapping_file = Path(mapping) if mapping is not None else mapping_path("voice")
    mapper = load_mapping(mapping_file)
    words = {} if script is None else {"script": script, "language": language}
    name, url = _voice_device(mapper, mapping_file, Path(sound), "offline" if lookahead else "live", words)
    device = WavDevice.from_url(Url.parse(url), name)
    device.load()
    layer = None if over is None else _mouth_layer(take_fap(over), mapper, name)
    base_frames = 0 if layer is None else _frame_count(layer.base_fap)
    folder = Path(folder)
    extra = {"t0_ns": 0, "hold_ns": None, "mapping_state": mapper.snapshot(),
             "wire": {name: device.wire_info()}, "layer": None if layer is None else layer.spec()}
    recorder = TakeRecorder(folder.parent, folder.name, fps, mapping_path=mapping_file, devices={name: url},
                            extra=extra, exact=True)
    try:
        clock = TakeClock(mapper, recorder.frame, 0, fps, layer=layer, encode_muscles=default_muscle_faps)
        for block, reading in device.readings():
            entry = Sample(block.start_ns + round(len(block.pcm) * 1e9 / block.rate), name, reading, block)
            recorder.sample(entry)
            clock.apply(entry)
        end = max(clock.tick_ns(base_frames - 1), device.blocks * device.block * 1_000_000_000 // device.rate)
        recorder.event(LogEvent(end, "frame"))
        clock.apply(LogEvent(end, "frame"))
    except BaseException as exc:
        recorder.abandon(f"lipsync stopped: {type(exc).__name__}: {exc}")
        raise
    return recorder.close()


def _voice_device(mapper, mapping_file: Path, sound: Path, mode: str, words: dict) -> tuple[str, str]:
    """The mapping's sound device (its name) and the ``wav://`` URL that plays ``sound`` in
    ``mode`` with the device's rate, block and gate."""
    for name, url in mapper.devices.items():
        parsed = Url.parse(url)
        if parsed.scheme in ("audio", "wav"):
            options = sound_options(parsed)
            query = urlencode({"rate": options["rate"], "block": options["block"], "gate": options["gate"],
                               "speed": 0, "mode": mode, **words})
            return name, f"wav://{quote(str(sound.resolve()))}?{query}"
    raise TakeError(f"{mapping_file}: no audio:// or wav:// device, so nothing in it follows a voice "
                    "(the shipped voice.yaml has one)")


def _mouth_layer(base_fap: Path, mapper, device: str) -> Layer:
    """A layer over ``base_fap`` whose mouth (and viseme, and whatever the voice drives) is armed."""
    mouth = [str(f.number) for f in faps() if f.group in MOUTH_GROUPS and f.number > 2]
    voiced = [channel for channel in mapper.channel_names if channel.startswith(f"{device}.")]
    return Layer.armed(base_fap, mapper, [*mouth, *voiced, "viseme"])


def _frame_count(path: Path) -> int:
    with iter_fap(path) as reader:
        return sum(1 for _ in reader)
