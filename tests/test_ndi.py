"""``--ndi``: the face as an NDI source with alpha, received on loopback by cyndilib's own receiver
(skipped without the ``ndi`` extra); straight alpha; and the refusal without the extra."""

from __future__ import annotations

import json
import os
import time
import uuid

import numpy as np
import pytest

from puppet import cli
from puppet.show.ndi import straight_alpha
from puppet.view.renderer import Renderer, aim_camera
from puppet.view.rendertake import head_points

SIZE = (160, 160)


def test_partly_covered_pixels_get_straight_colour_and_the_rest_is_kept():
    image = np.array([[[100, 50, 0, 128], [200, 100, 50, 255], [0, 0, 0, 0], [255, 255, 255, 64]]], dtype=np.uint8)
    straight = straight_alpha(image.copy())
    assert straight[0, 0].tolist() == [199, 100, 0, 128]
    assert straight[0, 1:3].tolist() == image[0, 1:3].tolist()
    assert straight[0, 3].tolist() == [255, 255, 255, 64]  # clipped, never wrapped


def test_without_the_extra_ndi_says_how_to_get_it(monkeypatch, capsys):
    monkeypatch.setitem(__import__("sys").modules, "cyndilib", None)
    assert cli.main(["play", "take.fap", "--ndi", "face"]) == 2
    assert capsys.readouterr().err.strip().startswith(
        "puppet play: --ndi needs cyndilib, the ndi extra: pip install \".[ndi]\" in facepuppet's folder, or pip")


@pytest.fixture(scope="module")
def ndi(tmp_path_factory):
    """cyndilib, with NDI told to look for sources on loopback (its mDNS may not reach here)."""
    folder = tmp_path_factory.mktemp("ndi")
    (folder / "ndi-config.v1.json").write_text(json.dumps({"ndi": {"networks": {"ips": "127.0.0.1"}}}))
    saved = os.environ.get("NDI_CONFIG_DIR")
    os.environ["NDI_CONFIG_DIR"] = str(folder)
    try:
        yield pytest.importorskip("cyndilib")
    finally:
        if saved is None:
            os.environ.pop("NDI_CONFIG_DIR", None)
        else:
            os.environ["NDI_CONFIG_DIR"] = saved


def _received(ndi, output, vertices, timeout: float = 20.0, skip: int = 3) -> np.ndarray:
    """A frame a receiver on this machine gets from ``output`` while ``vertices`` are published (after
    ``skip`` others, which may show what was published before)."""
    from cyndilib.finder import Finder
    from cyndilib.receiver import ReceiveFrameType, Receiver
    from cyndilib.video_frame import VideoRecvFrame
    from cyndilib.wrapper.ndi_recv import RecvBandwidth, RecvColorFormat

    finder = Finder()
    finder.open()
    receiver = Receiver(color_format=RecvColorFormat.RGBX_RGBA, bandwidth=RecvBandwidth.highest)
    frame = VideoRecvFrame()
    receiver.set_video_frame(frame)
    try:
        deadline = time.monotonic() + timeout
        while output.source_name not in finder.get_source_names():
            assert time.monotonic() < deadline, f"no NDI source {output.source_name}: {finder.get_source_names()}"
            finder.wait_for_sources(0.5)
        receiver.set_source(finder.get_source(output.source_name))
        while True:
            assert time.monotonic() < deadline, "the NDI source sent no frame"
            output.publish(vertices)
            time.sleep(0.02)  # cyndilib's receive holds the GIL while it waits: the sender's thread draws now
            if receiver.receive(ReceiveFrameType.recv_video, 10) & ReceiveFrameType.recv_video:
                data = np.empty(frame.get_data_size(), dtype=np.uint8)
                frame.fill_p_data(data)
                assert frame.get_resolution() == SIZE
                if skip == 0:
                    return data.reshape(SIZE[1], SIZE[0], 4)
                skip -= 1
    finally:
        receiver.disconnect()
        finder.close()


def test_a_receiver_on_loopback_gets_the_face_with_its_alpha(ndi, face, runtime):
    from puppet.show.ndi import NdiOutput

    camera = aim_camera(head_points(face), SIZE)
    output = NdiOutput(face, camera, f"facepuppet-test-{uuid.uuid4().hex[:8]}", SIZE)
    opened = runtime.deform_faps({"open_jaw": 600.0})
    try:
        rest_received = _received(ndi, output, face.vertices)
        open_received = _received(ndi, output, opened)
        output.service()
    finally:
        output.close()
    with Renderer.for_face(face, width=SIZE[0], height=SIZE[1], transparent=True) as renderer:
        renderer.camera = camera
        reference = [renderer.render(face.vertices), renderer.render(opened)]
    for received, expected in zip((rest_received, open_received), reference):  # NDI's codec is lossy, alpha too
        assert np.abs(received[..., 3].astype(int) - expected[..., 3]).max() <= 8
        opaque = expected[..., 3] == 255
        assert np.array_equal(received[..., 3] > 127, opaque)  # the face's outline, exactly
        difference = np.abs(received[opaque, :3].astype(int) - expected[opaque, :3])
        assert difference.mean() < 4 and np.percentile(difference, 99) < 24
    assert (rest_received[..., 3] != open_received[..., 3]).sum() > 50  # the open jaw reached the receiver
    assert output.sent >= 2
