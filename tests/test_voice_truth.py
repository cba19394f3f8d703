"""The mouth follows a speaker better than "mouth open = loud": measured against real speakers'
lips when their clips are at hand (``FACEPUPPET_VOICE_DATA``: see tools/checks/voice_truth.py; they are
not shipped), and always against a synthetic speaker whose lips are known, where an oo as loud
as an ah must not open the mouth as far."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest
from test_voice import RATE, vowel, write_wav

from puppet.bench.voicetruth import clip_from_video, clips, measure, read_lips
from puppet.cli import main
from puppet.live.lipsync import lipsync
from puppet.photo.detect import photo_python
from puppet.view.demo import demo_speech

VOICE_DATA = os.environ.get("FACEPUPPET_VOICE_DATA")

SYLLABLES = [("ah", 750, 1200, 1.0), ("oo", 300, 750, 0.25), ("ee", 280, 2350, 0.45)]
"""A synthetic speaker: each syllable's formants and how far its lips open (face widths x 10)."""


def synthetic_speaker(folder: Path, seed: int = 3) -> Path:
    """Syllables of equal loudness in a random order with pauses, and the lips that said them."""
    rng = np.random.default_rng(seed)
    sound = [np.zeros(int(0.3 * RATE))]
    plan = [(0.0, 0.3)]
    for _ in range(14):
        _, f1, f2, opening = SYLLABLES[rng.integers(len(SYLLABLES))]
        length = rng.uniform(0.18, 0.35)
        sound += [vowel(f1, f2, seconds=length, level=0.25), np.zeros(int(0.15 * RATE))]
        plan += [(opening, length), (0.0, 0.15)]
    wav = write_wav(folder / "synthetic.wav", np.concatenate(sound))
    edges = np.cumsum([0.0] + [length for _, length in plan])
    with open(folder / "synthetic_lips.csv", "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "t_s", "opening", "mouth_width", "face_width", "found"])
        for frame, t in enumerate(np.arange(0, edges[-1], 0.04)):
            k = min(int(np.searchsorted(edges, t, side="right")) - 1, len(plan) - 1)
            writer.writerow([frame, round(t, 3), plan[k][0] * 10, 40, 100, 1])
    return wav


def test_on_a_synthetic_speaker_the_rig_tells_open_vowels_from_loud_ones(tmp_path):
    synthetic_speaker(tmp_path)
    result = measure(tmp_path)["pooled"]
    assert result["offline"]["r"] > result["loudness"]["r"] + 0.15
    assert result["live"]["r"] > result["loudness"]["r"] + 0.15
    assert abs(result["offline"]["lag_ms"]) <= 80 and 0 <= result["live"]["lag_ms"] <= 100


@pytest.mark.skipif(not VOICE_DATA, reason="no real speakers' clips here (set FACEPUPPET_VOICE_DATA; "
                                           "tools/checks/voice_truth.py says what they hold)")
def test_against_real_speakers_the_mouth_follows_better_than_loudness():
    assert clips(VOICE_DATA), f"{VOICE_DATA}: no NAME.wav with NAME_lips.csv"
    result = measure(VOICE_DATA)
    pooled = result["pooled"]
    assert pooled["offline"]["r"] > pooled["loudness"]["r"] + 0.05
    assert pooled["live"]["r"] > pooled["loudness"]["r"] + 0.05
    better = [clip["offline"]["r"] > clip["loudness"]["r"] for clip in result["clips"].values()]
    assert sum(better) >= 0.8 * len(better)


@pytest.mark.skipif(photo_python() is None, reason="no photo environment (.venv-photo: tools/setup.sh makes it)")
def test_the_measure_sees_a_rendered_take_say_what_its_sound_says_in_sync(tmp_path, egl):
    """The whole chain, closed on itself: a take made from speech, rendered with its sound, then
    measured as a real speaker's video is (MediaPipe on every frame, the frames' times on the
    sound's clock) follows its own sound with no lag: the render keeps sound and picture in
    step, and the measure reads them as they are."""
    take = lipsync(demo_speech(), tmp_path / "take", fps=25)
    assert main(["render", str(take), "-o", str(tmp_path / "said.mp4"), "--size", "320x240"]) == 0
    clip_from_video(tmp_path / "said.mp4", tmp_path / "clips")
    truth_t, truth = read_lips(tmp_path / "clips" / "said_lips.csv")
    assert len(truth) >= 60                                      # a face in (nearly) every frame
    result = measure(tmp_path / "clips")["pooled"]
    assert result["offline"]["r"] > 0.8 and abs(result["offline"]["lag_ms"]) <= 20
