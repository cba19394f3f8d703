"""How well the mouth follows real speakers: the rig's lip gap, driven by sound alone, against
the lip opening measured on video of the person who spoke.

A clip is ``NAME.wav`` (the speaker's sound) beside ``NAME_lips.csv`` (per video frame: ``t_s``,
the inner-lip ``opening`` and the ``face_width`` in pixels, and ``found``, MediaPipe's face mesh
measured them). For each clip the sound is made into a take twice, with the offline analysis
(look-ahead, ``puppet lipsync``) and with the live one (what a microphone gives), and the default
face's inner-lip gap (feature points 2.2 to 2.3) is measured in every frame. The baseline is
"mouth open = loud": the sound's RMS envelope over a centred 20 ms window. Each is correlated with
the measured opening (Pearson) at every lag up to ``MAX_LAG_S``; a positive lag is the rig's mouth
moving after the speaker's. ``measure(folder)`` gives per clip and pooled (Fisher z mean)
figures; ``tools/checks/voice_truth.py`` prints them. ``clip_from_video`` makes a clip from a video
with sound (``tools/checks/voice_lips.py``): its sound track, and the lips measured in every frame by
MediaPipe in the photo environment (``puppet/photo/mediapipe_lips.py``), each frame's time
taken on the sound's clock.
"""

from __future__ import annotations

import csv
import json
import math
import re
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from devices.soundread import read_sound
from puppet.face.load import load_face
from puppet.fap.held import held_low_level
from puppet.fap.pose import Pose
from puppet.io.fapfile import iter_fap
from puppet.live.lipsync import lipsync
from puppet.photo.detect import DetectionError, photo_python
from puppet.runtime.runtime import Runtime

MAX_LAG_S = 0.2
LAG_STEP_S = 0.01
ENVELOPE_S = 0.02


def clips(folder: str | Path) -> list[Path]:
    """The clips (their .wav) in ``folder`` that have a ``_lips.csv`` beside them."""
    return sorted(p for p in Path(folder).glob("*.wav") if p.with_name(f"{p.stem}_lips.csv").is_file())


def read_lips(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The frames' times and the lip opening in face widths, where a face was found."""
    times, opening = [], []
    with open(path, newline="", encoding="utf-8") as file:
        for row in csv.DictReader(file):
            if row.get("found", "1") == "1" and float(row["face_width"]) > 0:
                times.append(float(row["t_s"]))
                opening.append(float(row["opening"]) / float(row["face_width"]))
    return np.array(times), np.array(opening)


def inner_lip_gap(face, vertices: np.ndarray) -> float:
    """How far apart the face's inner lips are (feature points 2.2 and 2.3) in ``vertices``."""
    return float(np.linalg.norm(vertices[face.feature_vertices["2.2"]] - vertices[face.feature_vertices["2.3"]]))


def lip_gap(take: Path, runtime: Runtime) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's time and the face's inner-lip gap in a take."""
    gaps = []
    with iter_fap(take / "take.fap") as reader:
        fps = reader.header.fps
        for values in held_low_level(reader):
            gaps.append(inner_lip_gap(runtime.face, runtime.deform_pose(Pose(values), normals=False)[0]))
    return np.arange(len(gaps)) / fps, np.array(gaps)


def loudness(wav: Path) -> tuple[np.ndarray, np.ndarray]:
    """The sound's RMS envelope every 10 ms (a centred ``ENVELOPE_S`` window)."""
    pcm, rate = read_sound(wav)
    x = pcm.astype(np.float64) / 32768.0
    half = int(ENVELOPE_S * rate / 2)
    hop = rate // 100
    centres = np.arange(0, len(x), hop)
    cumulative = np.concatenate([[0.0], np.cumsum(x * x)])
    low, high = np.clip(centres - half, 0, len(x)), np.clip(centres + half, 0, len(x))
    rms = np.sqrt((cumulative[high] - cumulative[low]) / np.maximum(high - low, 1))
    return centres / rate, rms


def correlate(truth_t: np.ndarray, truth: np.ndarray, t: np.ndarray, signal: np.ndarray) -> dict:
    """Pearson r of ``signal`` (at times ``t``) against ``truth`` at every lag; the best and lag 0."""
    lags = np.arange(-MAX_LAG_S, MAX_LAG_S + 1e-9, LAG_STEP_S)
    rs = []
    for lag in lags:
        predicted = np.interp(truth_t + lag, t, signal)
        rs.append(float(np.corrcoef(predicted, truth)[0, 1]) if np.std(predicted) > 0 else 0.0)
    best = int(np.argmax(rs))
    return {"r": rs[best], "lag_ms": round(float(lags[best]) * 1000), "r_at_0": rs[len(lags) // 2]}


def measure_clip(wav: Path, runtime: Runtime, work: Path) -> dict:
    """The offline, live and loudness figures of one clip."""
    truth_t, truth = read_lips(wav.with_name(f"{wav.stem}_lips.csv"))
    out = {"seconds": round(float(truth_t[-1]), 2), "frames": len(truth)}
    for name, lookahead in (("offline", True), ("live", False)):
        take = lipsync(wav, work / f"{wav.stem}_{name}", lookahead=lookahead)
        out[name] = correlate(truth_t, truth, *lip_gap(take, runtime))
    out["loudness"] = correlate(truth_t, truth, *loudness(wav))
    return out


def measure(folder: str | Path) -> dict:
    """Every clip's figures, and each method's pooled r (Fisher z mean) and median lag."""
    runtime = Runtime(load_face())
    found = clips(folder)
    with tempfile.TemporaryDirectory(prefix="facepuppet-voice-") as work:
        per_clip = {wav.stem: measure_clip(wav, runtime, Path(work)) for wav in found}
    pooled = {}
    for method in ("offline", "live", "loudness"):
        rs = [clip[method]["r"] for clip in per_clip.values()]
        r0 = [clip[method]["r_at_0"] for clip in per_clip.values()]
        pooled[method] = {"r": _fisher_mean(rs), "r_at_0": _fisher_mean(r0),
                          "lag_ms": float(np.median([clip[method]["lag_ms"] for clip in per_clip.values()]))}
    return {"clips": per_clip, "pooled": pooled}


LIPS = Path(__file__).resolve().parents[1] / "photo" / "mediapipe_lips.py"
SHOWN_AT = re.compile(r"\bn:\s*\d+\s+pts:\s*-?\d+\s+pts_time:\s*(-?[\d.eE+-]+)")


def clip_from_video(video: str | Path, folder: str | Path, name: str | None = None) -> Path:
    """Write ``NAME.wav`` (the video's sound, mono 48 kHz) and ``NAME_lips.csv`` (the lips in each
    frame, at its time on the sound's clock) into ``folder``; returns the .wav."""
    import imageio_ffmpeg

    ffmpeg, video, folder = imageio_ffmpeg.get_ffmpeg_exe(), Path(video), Path(folder)
    python = photo_python()
    if python is None:
        raise DetectionError("measuring lips needs the photo environment (.venv-photo: tools/setup.sh makes it)")
    name = name or video.stem
    folder.mkdir(parents=True, exist_ok=True)
    wav = folder / f"{name}.wav"
    subprocess.run([ffmpeg, "-v", "error", "-y", "-i", str(video), "-map", "0:a:0", "-ac", "1", "-ar", "48000",
                    "-c:a", "pcm_s16le", str(wav)], check=True)
    width, height = _size(ffmpeg, video)
    start = _shown_at(ffmpeg, video, "a")[0]
    times = [t - start for t in _shown_at(ffmpeg, video, "v")]
    decode = subprocess.Popen([ffmpeg, "-v", "error", "-i", str(video), "-map", "0:v:0", "-fps_mode", "passthrough",
                               "-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"], stdout=subprocess.PIPE)
    measured = subprocess.run([str(python), str(LIPS), str(width), str(height)], stdin=decode.stdout,
                              capture_output=True, text=True, check=True)
    decode.wait()
    with open(folder / f"{name}_lips.csv", "w", newline="", encoding="utf-8") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "t_s", "opening", "mouth_width", "face_width", "found"])
        for k, (t, line) in enumerate(zip(times, measured.stdout.splitlines())):
            row = json.loads(line)
            keys = ("opening", "mouth_width", "face_width")
            sizes = [round(row[key], 3) for key in keys] if row["found"] else [""] * len(keys)
            writer.writerow([k, round(t, 6), *sizes, int(row["found"])])
    return wav


def _size(ffmpeg: str, video: Path) -> tuple[int, int]:
    banner = subprocess.run([ffmpeg, "-hide_banner", "-i", str(video)], capture_output=True, text=True).stderr
    found = re.search(r"Video:.*?, (\d{2,5})x(\d{2,5})", banner)
    if found is None:
        raise ValueError(f"{video}: no video stream")
    return int(found.group(1)), int(found.group(2))


def _shown_at(ffmpeg: str, video: Path, stream: str) -> list[float]:
    """The presentation times (s) of a stream's frames, on the file's own clock."""
    show = ["-vf", "showinfo", "-fps_mode", "passthrough"] if stream == "v" else ["-af", "ashowinfo"]
    banner = subprocess.run([ffmpeg, "-hide_banner", "-nostats", "-copyts", "-i", str(video), "-map", f"0:{stream}:0",
                             *show, "-f", "null", "-"], capture_output=True, text=True).stderr
    return [float(t) for t in SHOWN_AT.findall(banner)]


def _fisher_mean(rs: list[float]) -> float:
    if not rs:
        return math.nan
    return float(np.tanh(np.mean(np.arctanh(np.clip(rs, -0.999, 0.999)))))
