"""OSC over loopback UDP: faders and VMC blendshape frames become Samples."""

from __future__ import annotations

import socket
import struct
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


def _message(address: bytes, tags: bytes = b",", payload: bytes = b"") -> bytes:
    def padded(raw: bytes) -> bytes:
        return raw + b"\0" * (4 - len(raw) % 4)
    return padded(address) + padded(tags) + payload


def _bundle(*elements: bytes) -> bytes:
    return b"#bundle\0" + b"\0" * 7 + b"\1" + b"".join(struct.pack(">i", len(e)) + e for e in elements)


def _nested(depth: int) -> bytes:
    datagram = _message(b"/deep", b",f", struct.pack(">f", 1.0))
    for _ in range(depth):
        datagram = _bundle(datagram)
    return datagram


BAD_DATAGRAMS = {
    "negative element size (python-osc loops forever)": _bundle() + struct.pack(">i", -4)
    + _message(b"/x", b",f", struct.pack(">f", 1.0)),
    "element size beyond the datagram": _bundle() + struct.pack(">i", 4096) + _message(b"/x"),
    "non-UTF-8 address": _message(b"/fader\xff\xfe", b",f", struct.pack(">f", 1.0)),
    "bundles nested 900 deep": _nested(900),
    "unknown type tag": _message(b"/x", b",Z"),
    "blob longer than the datagram": _message(b"/x", b",b", struct.pack(">i", 1 << 30)),
}


@pytest.mark.parametrize("what", BAD_DATAGRAMS)
def test_a_malformed_datagram_is_counted_and_the_device_reads_on(device, what):
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.sendto(BAD_DATAGRAMS[what], device.address)
    sender.close()
    deadline = time.monotonic() + 2
    while device.counters.bad_frames < 1 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert device.counters.bad_frames == 1
    _client(device).send_message("/fader/1", 0.5)
    assert [s.values for s in _samples(device, 1)] == [{"fader/1": 0.5}]
    assert device.state is State.OPEN


def test_bundles_nested_within_the_limit_are_read(device):
    from devices.osc_packet import MAX_DEPTH

    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.sendto(_nested(MAX_DEPTH), device.address)
    sender.close()
    assert [s.values for s in _samples(device, 1)] == [{"deep": 1.0}]


def test_blendshapes_never_applied_are_held_to_a_bound(device):
    from devices.osc_device import MAX_PENDING

    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    names = [f"shape{i}".encode() for i in range(MAX_PENDING + 200)]
    for first in range(0, len(names), 200):  # a few datagrams: a UDP flood may be dropped
        values = [_message(b"/VMC/Ext/Blend/Val", b",sf", name + b"\0" * (4 - len(name) % 4) + struct.pack(">f", 0.5))
                  for name in names[first:first + 200]]
        sender.sendto(_bundle(*values), device.address)
        time.sleep(0.02)
    sender.sendto(_message(b"/VMC/Ext/Blend/Apply"), device.address)
    sender.close()
    (sample,) = _samples(device, 1, timeout=5)
    assert len(sample.values) == MAX_PENDING
    assert device.counters.bad_frames == 200
