"""Draw docs/readme.gif, the README's picture: the default face following a simulated slider box.

The six sliders of ``sim://joystick`` (its default sines, 10-bit, read at 200 Hz) go through the
shipped ``arduino_sliders`` mapping, as ``puppet live --mapping arduino_sliders --device
"box=sim://joystick?protocol=ascii&rate=200"`` reads them, and the face is drawn headless beside
the sliders' positions, one frame every 1/FPS s.

    PYTHONPATH=. .venv/bin/python tools/figures/readme_gif.py [--out docs/readme.gif] [--seconds 6] [--size 300]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from PIL import Image, ImageDraw

from devices.base import Sample
from devices.simulated_serial import sine_sliders
from puppet.face.load import load_face
from puppet.io.shipped import shipped_mapping
from puppet.live.mappingfile import load_mapping
from puppet.runtime.runtime import Runtime
from puppet.view.renderer import Renderer

FPS = 12
READ_RATE = 200  # readings per second, as the README's first session asks of sim://joystick
LABELS = ("jaw", "smile L", "smile R", "brow L", "brow R", "blink")
PANEL = 110      # width of the sliders' panel, pixels


def sliders_panel(values: list[float], height: int) -> Image.Image:
    """The six sliders as vertical tracks with their knobs at ``values`` (0..1023), labelled."""
    panel = Image.new("RGB", (PANEL, height), (32, 34, 38))
    draw = ImageDraw.Draw(panel)
    step = PANEL // len(values)
    top, bottom = 12, height - 28
    for i, value in enumerate(values):
        x = step * i + step // 2
        draw.line([(x, top), (x, bottom)], fill=(90, 94, 100), width=3)
        y = bottom - (bottom - top) * value / 1023.0
        draw.rectangle([x - 6, y - 4, x + 6, y + 4], fill=(240, 180, 60))
        draw.text((x - 3, bottom + 6 + 9 * (i % 2)), LABELS[i][0] + LABELS[i][-1], fill=(200, 200, 200))
    return panel


def frames(seconds: float, size: int) -> list[Image.Image]:
    """The face posed by the mapping from the simulated sliders, beside them, FPS frames a second."""
    face = load_face()
    runtime = Runtime(face)
    mapping = load_mapping(shipped_mapping("arduino_sliders"))
    signal = sine_sliders()
    out = []
    with Renderer.for_face(face, width=size, height=size) as renderer:
        renderer.aim(runtime.deform_pose(mapping.pose(0))[0], view="front", margin=1.05)
        for k in range(round(seconds * READ_RATE)):
            t = k / READ_RATE
            values = signal(t)
            t_ns = round(t * 1e9)
            mapping.feed(Sample(t_ns, "box", {f"ch{i}": v for i, v in enumerate(values)}))
            if k % (READ_RATE // FPS) == 0:
                vertices, normals = runtime.deform_pose(mapping.pose(t_ns))
                picture = Image.new("RGB", (size + PANEL, size))
                picture.paste(Image.fromarray(renderer.render(vertices, normals)), (0, 0))
                picture.paste(sliders_panel(values, size), (size, 0))
                out.append(picture)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--out", type=Path, default=Path("docs/readme.gif"))
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--size", type=int, default=300, help="the face's square, pixels")
    args = parser.parse_args()
    pictures = frames(args.seconds, args.size)
    palette = pictures[len(pictures) // 2].quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    quantised = [p.quantize(palette=palette, dither=Image.Dither.NONE) for p in pictures]
    quantised[0].save(args.out, save_all=True, append_images=quantised[1:], duration=round(1000 / FPS),
                      loop=0, optimize=True)
    print(f"{args.out}: {len(quantised)} frames, {args.out.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
