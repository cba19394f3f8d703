"""The mouth following a voice, as a picture: docs/voice_sheet.png.

The demo's sentence (puppet/data/demo_speech.wav) made into takes by ``puppet lipsync`` three
ways -- live (what a microphone gives), offline (look-ahead) and offline with its script -- and
rendered close to the lips every 80 ms through the speech, a row each, under the sound's
waveform with the times marked. Prints where it wrote.

    python tools/figures/voice_sheet.py [--out docs/voice_sheet.png]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from devices.soundread import read_sound  # noqa: E402
from puppet.face.load import load_face  # noqa: E402
from puppet.fap.held import held_low_level  # noqa: E402
from puppet.fap.pose import Pose  # noqa: E402
from puppet.io.fapfile import iter_fap  # noqa: E402
from puppet.live.lipsync import lipsync  # noqa: E402
from puppet.runtime.runtime import Runtime  # noqa: E402
from puppet.view.demo import demo_speech  # noqa: E402
from puppet.view.renderer import Renderer  # noqa: E402

SCRIPT = "Hello! Nice to meet you."
FPS = 25
TIMES = np.arange(0.44, 2.4, 0.08)
TILE = (120, 90)
ROWS = (("live", {"lookahead": False}), ("offline", {}), ("offline + script", {"script": SCRIPT}))


def frames(take: Path, runtime: Runtime) -> list[np.ndarray]:
    """The take's poses (held FAPs) at ``TIMES``."""
    wanted = {round(t * FPS) for t in TIMES}
    out = {}
    with iter_fap(take / "take.fap") as reader:
        for k, values in enumerate(held_low_level(reader)):
            if k in wanted:
                out[k] = values.copy()
    return [out[round(t * FPS)] for t in TIMES]


def main(out: Path) -> None:
    face = load_face()
    runtime = Runtime(face)
    lips = face.vertices[[face.feature_vertices[p] for p in ("8.1", "8.2", "8.3", "8.4")]]
    strips = []
    with tempfile.TemporaryDirectory() as folder, \
            Renderer.for_face(face, width=TILE[0] * 2, height=TILE[1] * 2, detail=False) as renderer:
        renderer.aim(lips, view="front")
        for label, options in ROWS:
            take = lipsync(demo_speech(), Path(folder) / label.replace(" ", ""), fps=FPS, **options)
            tiles = [renderer.render(*runtime.deform_pose(Pose(values))) for values in frames(take, runtime)]
            strips.append((label, [np.asarray(Image.fromarray(t).resize(TILE)) for t in tiles]))
    pcm, rate = read_sound(demo_speech())
    half = (len(TIMES) + 1) // 2
    blocks = [_block(pcm, rate, TIMES[:half], [(label, tiles[:half]) for label, tiles in strips]),
              _block(pcm, rate, TIMES[half:], [(label, tiles[half:]) for label, tiles in strips])]
    sheet = Image.new("RGB", (max(b.width for b in blocks), sum(b.height for b in blocks) + 24), (255, 255, 255))
    ImageDraw.Draw(sheet).text((6, 6), f'"{SCRIPT}" (puppet/data/demo_speech.wav): the mouth every 80 ms',
                               fill=(0, 0, 0))
    y = 24
    for block in blocks:
        sheet.paste(block, (0, y))
        y += block.height
    out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(out)
    print(out)


def _block(pcm: np.ndarray, rate: int, times: np.ndarray, rows: list[tuple[str, list[np.ndarray]]]) -> Image.Image:
    """The waveform over ``times`` and, under it, a row of tiles per method."""
    width = TILE[0] * len(times)
    block = Image.new("RGB", (width + 110, 60 + len(rows) * TILE[1]), (255, 255, 255))
    draw = ImageDraw.Draw(block)
    span = (times[0] - 0.04, times[-1] + 0.04)
    for x in range(width):
        t0, t1 = span[0] + (span[1] - span[0]) * np.array([x, x + 1]) / width
        chunk = pcm[int(t0 * rate):int(t1 * rate)].astype(float) / 32768
        if len(chunk):
            draw.line([(110 + x, 28 - 26 * chunk.max()), (110 + x, 28 - 26 * chunk.min())], fill=(60, 60, 140))
    for k, t in enumerate(times):
        draw.text((110 + k * TILE[0] + 4, 46), f"{t:.2f} s", fill=(0, 0, 0))
    for r, (label, tiles) in enumerate(rows):
        block.paste(Image.fromarray(np.hstack(tiles)), (110, 60 + r * TILE[1]))
        draw.text((6, 60 + r * TILE[1] + TILE[1] // 2 - 6), label, fill=(0, 0, 0))
    return block


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/voice_sheet.png"))
    main(parser.parse_args().out)
