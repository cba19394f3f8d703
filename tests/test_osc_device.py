"""OSC over loopback UDP: faders and VMC blendshape frames become Samples."""

from __future__ import annotations

import socket
import time

import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import SimpleUDPClient

from devices import open_device
from devices.base import State
from devices.osc_device import OscDevice


@pytest.fixture
def device():
    dev = OscDevice("phone", "127.0.0.1", 0).start()
    assert dev.wait_state(State.OPEN, 2.0)
    yield dev
    dev.close()


def _client(device) -> SimpleUDPClient:
    return SimpleUDPClient(*device.address)


def _samples(device, n: int, timeout: float = 2.0) -> list:
    got = []
    deadline = time.monotonic() + timeout
    while len(got) < n and time.monotonic() < deadline:
        got += device.drain()
        time.sleep(0.005)
    return got


def test_a_fader_message_is_a_channel(device):
    _client(device).send_message("/fader/1", 0.25)
    _client(device).send_message("/xy", [0.5, 0.75])
    got = _samples(device, 2)
    assert [s.values for s in got] == [{"fader/1": 0.25}, {"xy": 0.5}]


def test_vmc_blendshapes_arrive_as_one_sample_per_apply(device):
    client = _client(device)
    for name, value in (("JawOpen", 0.4), ("MouthSmile_L", 0.7), ("EyeBlink_R", 1.0)):
        client.send_message("/VMC/Ext/Blend/Val", [name, value])
    client.send_message("/VMC/Ext/Blend/Apply", [])
    (sample,) = _samples(device, 1)
    assert sample.values == pytest.approx({"JawOpen": 0.4, "MouthSmile_L": 0.7, "EyeBlink_R": 1.0})


def test_a_bundle_is_read_in_order(device):
    bundle = OscBundleBuilder(IMMEDIATELY)
    for i in range(3):
        message = OscMessageBuilder("/slider")
        message.add_arg(float(i))
        bundle.add_content(message.build())
    socket.socket(socket.AF_INET, socket.SOCK_DGRAM).sendto(bundle.build().dgram, device.address)
    assert [s.values["slider"] for s in _samples(device, 3)] == [0.0, 1.0, 2.0]


def test_garbage_datagrams_are_counted_and_skipped(device):
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.sendto(b"\x00\xffnot osc at all", device.address)
    _client(device).send_message("/label", "text only")
    _client(device).send_message("/fader/2", 0.5)
    got = _samples(device, 1)
    assert [s.values for s in got] == [{"fader/2": 0.5}]
    assert device.counters.bad_frames == 2


def test_an_osc_url_binds_loopback_by_default():
    dev = open_device("osc://127.0.0.1:0", name="tracker")
    assert isinstance(dev, OscDevice) and dev.host == "127.0.0.1"
    with dev:
        assert dev.wait_state(State.OPEN, 2.0)
        assert dev.address[0] == "127.0.0.1" and dev.address[1] > 0
