"""The program feed's page in a real browser (headless Chromium, as OBS's Browser Source is): the
face alone on a transparent background, drawn like the desktop renderer draws it, following the
frames the rig publishes."""

from __future__ import annotations

import time

import numpy as np
import pytest

from puppet.bench.browser import HeadlessChromium, find_browser
from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime
from puppet.show.server import ShowServer
from puppet.view.renderer import Renderer
from puppet.view.rendertake import aim_at_head

pytestmark = pytest.mark.skipif(find_browser() is None, reason="no Chromium here (tools/setup.sh installs it)")

SIZE = (480, 480)
DRAWN = "window.facepuppet && window.facepuppet.number >= {} && window.facepuppet.drawn > 0"


@pytest.fixture(scope="module")
def face():
    return load_face()


@pytest.fixture(scope="module", params=["pixel", "vertex"])
def shading(request):
    return request.param


@pytest.fixture(scope="module")
def reference(face, shading):
    """The desktop renderer on a transparent backdrop, lit per pixel or per vertex with no
    antialiasing (the page's draw with ``antialias=0`` and that ``shading``), and its camera."""
    renderer = Renderer.for_face(face, width=SIZE[0], height=SIZE[1], transparent=True, shading=shading,
                                 antialias="none", samples=0, detail=False)
    aim_at_head(renderer, face, "front")
    yield renderer
    renderer.release()


@pytest.fixture(scope="module")
def page(face, reference, shading):
    with ShowServer(face, reference.camera, port=0, size=SIZE) as server, HeadlessChromium(SIZE) as browser:
        browser.open(server.page_url + f"&antialias=0&shading={shading}")
        yield server, browser


def _shown(server, browser, vertices: np.ndarray) -> np.ndarray:
    number = server._encoder.number + 1
    server.publish(vertices)
    browser.wait_for(DRAWN.format(number))
    time.sleep(0.1)  # the compositor's next frame
    return browser.screenshot()


def test_the_page_shows_the_face_as_the_renderer_does_on_a_transparent_background(face, reference, page):
    server, browser = page
    shot = _shown(server, browser, face.vertices)
    want = reference.render(face.vertices)
    assert shot.shape == want.shape
    assert shot[0, 0, 3] == 0 and shot[-1, -1, 3] == 0  # corners: nothing drawn
    covered = want[..., 3] > 0
    assert covered.mean() > 0.2
    assert (shot[..., 3] != want[..., 3]).mean() < 0.001  # the silhouette, to a few edge pixels
    difference = np.abs(shot[..., :3].astype(int) - want[..., :3]).max(axis=2)[covered]
    assert difference.mean() < 0.5 and np.percentile(difference, 99) <= 2


def test_the_page_follows_the_rig_where_the_mouth_moves(face, reference, page):
    server, browser = page
    runtime = Runtime(face)
    rest = _shown(server, browser, face.vertices)
    opened = runtime.deform_faps({"open_jaw": 600})
    shot = _shown(server, browser, opened)
    mouth = reference.project(face.feature_points["8.1"][None])[0].astype(int)  # upper lip, middle
    changed = np.abs(shot.astype(int) - rest).max(axis=2) > 20
    near = changed[mouth[1]:mouth[1] + 60, mouth[0] - 40:mouth[0] + 40]
    assert near.mean() > 0.2
    assert not changed[:mouth[1] - 120].any()  # the brow and above stay still
    assert server.delays_ms and max(server.delays_ms) < 2000
