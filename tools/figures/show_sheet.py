"""The program feed as OBS would key it: the page in headless Chromium beside the desktop render.

Writes ``docs/show_feed.png``: for the rest pose and an open, smiling mouth, the page's screenshot
(its transparency shown over a checkerboard, as an editor shows alpha) and the desktop renderer's
frame of the same vertices on a transparent backdrop, and their difference (x8).

    python tools/figures/show_sheet.py [-o docs/show_feed.png]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from puppet.bench.browser import HeadlessChromium
from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.show.server import ShowServer
from puppet.view.renderer import Renderer
from puppet.view.rendertake import aim_at_head

SIZE = (360, 360)


def checkerboard(image: np.ndarray, square: int = 12) -> np.ndarray:
    """RGBA over a grey checkerboard, as RGB."""
    rows, cols = np.indices(image.shape[:2]) // square
    board = np.where(((rows + cols) % 2)[..., None] == 0, 200, 150).astype(float)
    alpha = image[..., 3:4] / 255.0
    return (image[..., :3] * alpha + board * (1 - alpha)).astype(np.uint8)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default="docs/show_feed.png")
    out = Path(parser.parse_args().output)
    face = load_face()
    runtime = Runtime(face)
    poses = {"rest": face.vertices,
             "open, smiling": runtime.deform_faps({"open_jaw": 500, "stretch_l_cornerlip": 250,
                                                   "stretch_r_cornerlip": 250, "raise_l_cornerlip": 150,
                                                   "raise_r_cornerlip": 150})}
    renderer = Renderer.for_face(face, width=SIZE[0], height=SIZE[1], transparent=True, shading="pixel",
                                 antialias="none", samples=0, detail=False)
    aim_at_head(renderer, face, "front")
    rows = []
    with ShowServer(face, renderer.camera, port=0, size=SIZE) as server, HeadlessChromium(SIZE) as browser:
        browser.open(server.page_url + "&antialias=0")
        for label, vertices in poses.items():
            number = server._encoder.number + 1
            server.publish(vertices)
            browser.wait_for(f"window.facepuppet && window.facepuppet.number >= {number}")
            time.sleep(0.2)
            page, desk = browser.screenshot(), renderer.render(vertices)
            difference = np.clip(np.abs(page.astype(int) - desk.astype(int))[..., :3] * 8, 0, 255).astype(np.uint8)
            rows.append((label, [checkerboard(page), checkerboard(desk), difference]))
    renderer.release()
    titles = ["the page (Chromium)", "the desktop renderer", "difference x8"]
    sheet = Image.new("RGB", (SIZE[0] * 3, (SIZE[1] + 20) * len(rows) + 20), "white")
    draw = ImageDraw.Draw(sheet)
    for c, title in enumerate(titles):
        draw.text((c * SIZE[0] + 8, 4), title, fill="black")
    for r, (label, images) in enumerate(rows):
        top = 20 + r * (SIZE[1] + 20)
        draw.text((8, top + 4), label, fill="black")
        for c, image in enumerate(images):
            sheet.paste(Image.fromarray(image), (c * SIZE[0], top + 20))
    out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(out)
    print(out)


if __name__ == "__main__":
    main()
