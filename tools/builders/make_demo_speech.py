"""Write puppet/data/demo_speech.wav (see DEMO_SPEECH.md there): the demo take's sentence, spoken.

espeak-ng (apt) says "Hello! Nice to meet you." in US English; the speech is put 0.4 s into the
file, where the shipped demo take (tools/builders/make_demo_take.py) starts to speak, and saved as 16-bit
mono 22,050 Hz WAV. ``puppet demo`` lays the mouth this sound makes (``puppet lipsync --over``)
over the demo take and renders both, with the sound.

    python tools/builders/make_demo_speech.py [--out PATH]
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from devices.soundread import read_sound
from puppet.io.wavwriter import WavWriter

SENTENCE = "Hello! Nice to meet you."
LEAD_S = 0.4
OUT = Path(__file__).resolve().parents[2] / "puppet" / "data" / "demo_speech.wav"


def speak(text: str, out: Path, lead_s: float = LEAD_S) -> None:
    """``text`` spoken by espeak-ng into ``out``, after ``lead_s`` of silence."""
    with tempfile.TemporaryDirectory() as folder:
        raw = Path(folder) / "speech.wav"
        subprocess.run(["espeak-ng", "-v", "en-us", "-s", "150", "-w", str(raw), text], check=True)
        pcm, rate = read_sound(raw)
    with WavWriter(out, rate) as writer:
        writer.write(np.concatenate([np.zeros(round(lead_s * rate), np.int16), pcm]))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    speak(SENTENCE, parser.parse_args().out)
