"""A rendered take's video with its sound: AAC muxed in by the ffmpeg the project bundles.

``write_video_with_sound`` encodes the frames (``renderer.write_video``) and, for a take with a
soundtrack, adds it: the picture goes to a hidden file beside ``out`` first, removed after. The
soundtrack (``puppet.io.soundtrack``) starts on frame 0 and is cut to the video's length;
ffmpeg copies the video stream and encodes the sound as AAC, and its MP4 edit list hides the AAC
encoder's priming, so the first sample plays with the first frame.
"""

from __future__ import annotations

import subprocess
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from puppet.io.soundtrack import Soundtrack
from puppet.io.wavwriter import WavWriter
from puppet.view.renderer import write_video

AUDIO_BITRATE = "192k"


def write_video_with_sound(frames: Iterable[np.ndarray], out: Path, fps: float, sound: Soundtrack | None) -> int:
    """Encode ``frames`` to the MP4 ``out`` at ``fps`` with ``sound`` as its track (none when
    None); return the frame count."""
    if sound is None:
        return write_video(frames, out, fps)
    silent = out.with_name(f".{out.stem}.silent{out.suffix}")
    try:
        count = write_video(frames, silent, fps)
        mux_sound(silent, sound, count, fps, out)
    finally:
        silent.unlink(missing_ok=True)
    return count


def mux_sound(video: Path, sound: Soundtrack, frames: int, fps: float, out: Path) -> None:
    """Write ``out``: ``video`` with ``sound`` as its AAC track, as long as its ``frames``."""
    import imageio_ffmpeg

    length = round(frames / fps * sound.rate)
    pcm = sound.pcm[:length]
    with tempfile.TemporaryDirectory(prefix="facepuppet-sound-") as folder:
        wav = Path(folder) / "sound.wav"
        with WavWriter(wav, sound.rate) as writer:
            writer.write(np.concatenate([pcm, np.zeros(max(0, length - len(pcm)), np.int16)]))
        command = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-i", str(video), "-i", str(wav),
                   "-map", "0:v:0", "-map", "1:a:0", "-c:v", "copy", "-c:a", "aac", "-b:a", AUDIO_BITRATE,
                   "-movflags", "+faststart", str(out)]
        done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise OSError(f"{out}: ffmpeg could not add the sound: {done.stderr.strip().splitlines()[-1:]}")
