"""HID: report descriptor parsing, field extraction (against an independent bit packer), and
HidDevice over the fake hid module: named samples, bad reports, unplug and replug, prompt close."""

from __future__ import annotations

import itertools
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from polling import wait_for

from devices import DeviceError, State, Url, open_device
from devices.hid_descriptor import (
    AXIS,
    BUTTON_KIND,
    HAT_KIND,
    RAW,
    Channel,
    DescriptorError,
    ReportDecoder,
    ReportLayout,
    channels_of,
    parse_descriptor,
)
from devices.hid_device import HidDevice, discover
from devices.simulated_hid import (
    GAMEPAD_DESCRIPTOR,
    FakeHidHardware,
    FakeHidModule,
    gamepad,
    gamepad_motion,
    gamepad_report,
    knobs_report,
)

STICKS = ["X", "Y", "Rx", "Ry"]
BUTTONS = [f"button{k}" for k in range(1, 13)]


# -- the descriptor ------------------------------------------------------------------------------

def test_the_gamepad_descriptor_gives_named_fields_where_they_are():
    fields = parse_descriptor(GAMEPAD_DESCRIPTOR)
    assert [(f.report_id, f.bit_offset, f.bit_size, f.count, f.logical_min, f.logical_max, f.signed)
            for f in fields] == [
        (1, 0, 16, 4, -32768, 32767, True),   # sticks
        (1, 64, 8, 2, 0, 255, False),         # triggers
        (1, 80, 1, 12, 0, 1, False),          # buttons
        (1, 92, 4, 1, 0, 7, False),           # hat (the pad byte after it is Constant: no field)
        (2, 0, 10, 2, 0, 1023, False),        # knobs: report 2 starts its own bit count
    ]
    channels = channels_of(fields)
    assert [c.name for c in channels] == STICKS + ["Z", "Rz"] + BUTTONS + ["hat", "Slider", "Dial"]
    kinds = {c.name: c.kind for c in channels}
    assert kinds["X"] == AXIS and kinds["button12"] == BUTTON_KIND and kinds["hat"] == HAT_KIND
    assert [c.bit_offset for c in channels if c.name.startswith("button")] == list(range(80, 92))
    layout = ReportLayout(channels)
    assert layout.numbered and layout.report_length == 13  # id byte + 12 bytes the fields reach


def test_descriptor_items_long_extended_usages_push_pop_arrays_and_the_unsigned_max_slip():
    desc = bytes([
        0x05, 0x01, 0x09, 0x04, 0xA1, 0x01,    # Generic Desktop, Joystick, Collection
        0xFE, 0x02, 0x10, 0xAA, 0xBB,          # a long item: skipped whole
        0x0B, 0x38, 0x00, 0x01, 0x00,          # Usage (Generic Desktop: Wheel), 4-byte extended
        0x15, 0x00, 0x25, 0xFF,                # Logical 0..0xFF written as 1 signed byte (-1)
        0x75, 0x08, 0x95, 0x01, 0x81, 0x02,    # 8 bits, Input
        0xA4,                                  # Push
        0x05, 0x02, 0x09, 0xBB,                # Simulation Controls: Throttle
        0x15, 0x81, 0x25, 0x7F, 0x81, 0x02,    # -127..127, Input
        0xB4,                                  # Pop: 0..255 again, page Generic Desktop
        0x05, 0x07, 0x19, 0x00, 0x29, 0x65,    # Keyboard page, usages 0..0x65
        0x95, 0x02, 0x81, 0x00,                # Input (Data, Array): two key slots
        0x09, 0x30, 0x95, 0x01, 0x81, 0x02,    # X on the Keyboard page (unknown usage)
        0x09, 0x30, 0x05, 0x01, 0x09, 0x30, 0x95, 0x02, 0x81, 0x02,  # two more "X"
        0xC0,
    ])
    fields = parse_descriptor(desc)
    assert fields[0].usages == ((0x01, 0x38),) and (fields[0].logical_min, fields[0].logical_max) == (0, 255)
    assert fields[1].usages == ((0x02, 0xBB),) and fields[1].signed
    assert not fields[2].variable
    names = [c.name for c in channels_of(fields)]
    assert names == ["Wheel", "Throttle", "array1", "array2", "key_0030", "key_0030_2", "X"]
    layout = ReportLayout.from_descriptor(desc)
    assert not layout.numbered
    values = layout.decode(bytes([255, 0x81, 4, 5, 9, 0, 0]))
    assert values["Wheel"] == 1.0 and values["Throttle"] == -1.0
    assert (values["array1"], values["array2"]) == (4.0, 5.0)


@pytest.mark.parametrize("bad, message", [
    (bytes([0x05]), "needs 1 data bytes"),
    (bytes([0xC0]), "End Collection without Collection"),
    (bytes([0xB4]), "Pop without Push"),
    (bytes([0x85, 0x00]), "Report ID 0"),
])
def test_broken_descriptors_name_the_byte(bad, message):
    with pytest.raises(DescriptorError, match=message):
        parse_descriptor(bad)


# -- field extraction against an independent packer ---------------------------------------------

def pack(fields: list[tuple[int, int, int]], nbytes: int) -> bytes:
    """Bit by bit, as the HID spec draws it: value bit i goes to report bit offset + i, report bit
    b being bit b % 8 of byte b // 8. ``fields``: (bit_offset, bit_size, value)."""
    out = bytearray(nbytes)
    for offset, size, value in fields:
        value &= (1 << size) - 1  # two's complement for negatives
        for i in range(size):
            if value >> i & 1:
                out[(offset + i) // 8] |= 1 << ((offset + i) % 8)
    return bytes(out)


@st.composite
def layouts(draw):
    """Random channels (1..32 bits, signed or not, odd offsets and gaps) with values in range."""
    n = draw(st.integers(1, 8))
    offset = draw(st.integers(0, 13))
    channels, values = [], []
    for k in range(n):
        size = draw(st.integers(1, 32))
        if draw(st.booleans()) and size > 1:
            lo, hi = -(1 << (size - 1)), (1 << (size - 1)) - 1
            lo = draw(st.integers(lo, -1))
            hi = draw(st.integers(1, hi))
        else:
            lo = draw(st.integers(0, (1 << size) - 2)) if size > 1 else 0
            hi = draw(st.integers(lo + 1, (1 << size) - 1))
        channels.append(Channel(f"c{k}", 0, offset, size, lo, hi, AXIS))
        values.append(draw(st.integers(lo, hi)))
        offset += size + draw(st.integers(0, 11))
    return channels, values


def expected_scaled(c: Channel, v: int) -> float:
    if c.logical_min < 0:
        return v / c.logical_max if v >= 0 else v / -c.logical_min
    return (v - c.logical_min) / (c.logical_max - c.logical_min)


@settings(max_examples=300, deadline=None)
@given(layouts(), st.integers(0, 3), st.binary(min_size=0, max_size=3))
def test_extraction_gives_back_what_was_packed(layout, slack, tail):
    channels, values = layout
    nbytes = max((c.bit_offset + c.bit_size + 7) // 8 for c in channels) + slack
    data = pack([(c.bit_offset, c.bit_size, v) for c, v in zip(channels, values)], nbytes) + tail
    raw = ReportDecoder(channels, raw=True)
    assert raw.decode(data) == {c.name: float(v) for c, v in zip(channels, values)}
    scaled = ReportDecoder(channels).decode(data)
    assert scaled == pytest.approx({c.name: expected_scaled(c, v) for c, v in zip(channels, values)},
                                   abs=1e-12)
    assert all(-1.0 <= x <= 1.0 for x in scaled.values())
    # the numpy path over a batch gives the same, row by row
    batch = np.frombuffer(data * 3, np.uint8).reshape(3, len(data))
    arr = ReportDecoder(channels).decode_array(batch)
    assert np.allclose(arr, [[scaled[c.name] for c in channels]] * 3, atol=1e-12)
    assert np.array_equal(raw.decode_array(batch)[0], values)
    # with a report ID byte in front, the same values
    numbered = ReportLayout([Channel(c.name, 7, c.bit_offset, c.bit_size, c.logical_min, c.logical_max)
                             for c in channels], raw=True)
    assert numbered.decode(bytes([7]) + data) == raw.decode(data)
    assert numbered.decode(data, has_id=False) == raw.decode(data)  # one report ID: either form
    assert numbered.decode(bytes([8]) + data) is None  # unknown report ID


def test_buttons_hat_and_clamping():
    layout = ReportLayout.from_descriptor(GAMEPAD_DESCRIPTOR)
    v = layout.decode(gamepad_report(x=-32768, y=32767, rx=-16384, z=255, rz=51, buttons=0b1000_0000_0101, hat=3))
    assert (v["X"], v["Y"], v["Rx"], v["Ry"]) == (-1.0, 1.0, -0.5, 0.0)
    assert (v["Z"], v["Rz"]) == (1.0, 0.2)
    assert [v[b] for b in BUTTONS] == [1, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 1]
    assert v["hat"] == 135.0
    assert layout.decode(gamepad_report(hat=8))["hat"] == -1.0  # null state: centred
    assert layout.decode(gamepad_report(hat=0))["hat"] == 0.0
    assert layout.decode(knobs_report(1023, 0)) == {"Slider": 1.0, "Dial": 0.0}
    assert layout.decode(gamepad_report()[:12]) is None  # shorter than its fields
    out_of_range = ReportDecoder([Channel("a", 0, 0, 8, 0, 100)])
    assert out_of_range.decode(bytes([200])) == {"a": 1.0}
    assert ReportDecoder([Channel("r", 0, 0, 8, 0, 100, RAW)]).decode(bytes([200])) == {"r": 200.0}


# -- HidDevice over the fake module -----------------------------------------------------------------

def fast(device: HidDevice) -> HidDevice:
    device.BACKOFF = (0.01, 0.05)
    return device


def hid_device(module: FakeHidModule, url: str = "hid://046d:c21d", **kw) -> HidDevice:
    return fast(HidDevice.from_url(Url.parse(url), "pad", hid_module=module, **kw))


def test_a_gamepad_gives_samples_named_by_its_descriptor():
    pad = gamepad()
    module = FakeHidModule(pad)
    with hid_device(module) as device:
        assert device.wait_state(State.OPEN, 2.0)
        pad.feed(gamepad_report(x=32767, y=-32768, z=255, buttons=0b11, hat=2), knobs_report(0, 1023))
        got = []
        for sample in device.samples(timeout=2.0):
            got.append(sample)
            if len(got) == 2:
                break
    assert set(got[0].values) == set(STICKS + ["Z", "Rz", "hat"] + BUTTONS)
    assert got[0].values["X"] == 1.0 and got[0].values["Y"] == -1.0 and got[0].values["Z"] == 1.0
    assert got[0].values["button1"] == got[0].values["button2"] == 1.0 and got[0].values["button3"] == 0.0
    assert got[0].values["hat"] == 90.0
    assert got[1].values == {"Slider": 0.0, "Dial": 1.0}
    assert got[0].device == "pad" and got[0].t_ns <= got[1].t_ns
    assert device.info == {"manufacturer": "facepuppet", "product": "Fake Game Pad"}
    assert device.counters.bad_frames == 0


def test_garbage_and_short_reports_are_counted_and_skipped():
    pad = gamepad()
    with hid_device(FakeHidModule(pad)) as device:
        assert device.wait_state(State.OPEN, 2.0)
        pad.feed(b"\x01\x02\x03",                  # report 1, cut short
                 b"\x09" + bytes(13),               # a report ID the descriptor does not declare
                 b"\x02\x01",                       # report 2, cut short
                 gamepad_report(x=-32768))
        sample = next(device.samples(timeout=2.0))
        assert sample.values["X"] == -1.0
        assert device.counters.bad_frames == 3
        assert device.drain() == []


def test_every_queued_report_becomes_a_sample_in_order():
    pad = gamepad()
    reports = list(itertools.islice(gamepad_motion(), 5 * HidDevice.BATCH + 3))  # several batches
    with hid_device(FakeHidModule(pad)) as device:
        assert device.wait_state(State.OPEN, 2.0)
        pad.feed(*reports)
        assert wait_for(lambda: device.counters.samples >= len(reports))
        time.sleep(0.05)
        samples = device.drain()
    layout = ReportLayout.from_descriptor(GAMEPAD_DESCRIPTOR)
    assert [s.values for s in samples] == [layout.decode(r) for r in reports]
    assert device.counters.samples == len(reports) and pad.reads == len(reports)


def test_close_is_prompt_while_a_read_waits():
    module = FakeHidModule(gamepad())
    device = hid_device(module).start()
    assert device.wait_state(State.OPEN, 2.0)
    time.sleep(0.05)  # the reader is inside read(n, timeout_ms) now
    start = time.monotonic()
    device.close()
    assert time.monotonic() - start < 0.5
    assert device.state == State.CLOSED and module.opened[-1]._hw is None


def test_the_gamepad_motion_stays_in_range_over_a_whole_period():
    layout = ReportLayout.from_descriptor(GAMEPAD_DESCRIPTOR)
    values = [layout.decode(r) for r in itertools.islice(gamepad_motion(period=200), 400)]
    assert None not in values
    sticks = [v[k] for v in values for k in STICKS + ["Z", "Rz", "Slider", "Dial"] if k in v]
    assert min(sticks) <= -0.99 and max(sticks) >= 0.99 and all(-1 <= x <= 1 for x in sticks)
    assert {v["hat"] for v in values if "hat" in v} == {-1.0, 0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0}


def test_an_endless_performance_at_a_rate():
    pad = gamepad(gamepad_motion(), rate=500)
    with hid_device(FakeHidModule(pad)) as device:
        assert wait_for(lambda: device.counters.samples >= 20)
        samples = device.drain()
    assert {s.values.get("X") is not None or s.values.get("Slider") is not None for s in samples} == {True}
    assert device.counters.bad_frames == 0


def test_fields_by_hand_for_a_device_without_a_descriptor():
    box = FakeHidHardware(0x16C0, 0x05DC, None, serial="BOX1")
    url = "hid://16c0:05dc:BOX1?fields=knob:0:12;fader:12:12:0:4000;go:24:1;turn:25:7:-64:63"
    with hid_device(FakeHidModule(box), url) as device:
        assert device.wait_state(State.OPEN, 2.0)
        box.feed((4095 | 2000 << 12 | 1 << 24 | (-64 & 0x7F) << 25).to_bytes(4, "little"))
        assert next(device.samples(timeout=2.0)).values == {"knob": 1.0, "fader": 0.5, "go": 1.0, "turn": -1.0}


def test_a_device_without_a_descriptor_or_fields_says_what_to_do():
    with hid_device(FakeHidModule(FakeHidHardware(0x16C0, 0x05DC, None)), "hid://16c0:05dc") as device:
        assert wait_for(lambda: "fields=" in device.counters.last_error)
        assert device.state in (State.LOST, State.OPENING)


def test_an_unplugged_pad_says_it_is_not_plugged_in_and_its_handles_are_closed():
    """What only HID adds to the device contract (tests/test_device_contract.py): hidapi's bare
    "open failed" told apart, and no handle left open across unplug and replug."""
    pad = gamepad()
    module = FakeHidModule(pad)
    with hid_device(module) as device:
        assert device.wait_state(State.OPEN, 2.0)
        pad.unplug()
        assert wait_for(lambda: device.counters.last_error == "not plugged in: no HID device 046d:c21d plugged in")
        pad.replug()
        assert device.wait_state(State.OPEN, 2.0)
    assert all(h._hw is None for h in module.opened)


def test_interfaces_and_paths():
    pad = gamepad()
    other = FakeHidHardware(0x046D, 0xC21D, GAMEPAD_DESCRIPTOR, serial="B", interface_number=1)
    module = FakeHidModule(pad, other)
    with hid_device(module, "hid://046d:c21d?interface=1") as device:
        assert device.wait_state(State.OPEN, 2.0)
        other.feed(gamepad_report(x=32767))
        assert next(device.samples(timeout=2.0)).values["X"] == 1.0
    found, _ = discover(module)
    url = found.url
    assert url == "hid://path/fake-hid%3A046d%3Ac21d%3AFAKE0001" and "interface 0" in found.description
    with hid_device(module, url) as device:
        assert device.wait_state(State.OPEN, 2.0)
        pad.feed(gamepad_report(y=32767))
        assert next(device.samples(timeout=2.0)).values["Y"] == 1.0
    assert HidDevice.from_url(Url.parse("hid://046d:c21d:SN%3A1"), "x", hid_module=module).serial == "SN:1"


@pytest.mark.parametrize("url, message", [
    ("hid://046d", "expected hid://VID:PID"),
    ("hid://zz:c21d", "hex"),
    ("hid://path/", "url-encoded path"),
    ("hid://046d:c21d?bogus=1", "unknown option"),
    ("hid://046d:c21d?fields=a:0", "expected name:bit_offset:bit_size"),
    ("hid://046d:c21d?fields=a:0:40", "size of 1..32"),
    ("hid://046d:c21d?report_id=2", "report_id only goes with fields"),
])
def test_bad_urls_say_what_was_expected(url, message):
    with pytest.raises(DeviceError, match=message):
        HidDevice.from_url(Url.parse(url), "x", hid_module=FakeHidModule())


def test_a_device_that_is_plugged_in_but_will_not_open_points_at_permissions(monkeypatch):
    def refuse(self, *args):
        raise OSError("open failed")  # what hidapi says when /dev/hidraw* is not readable

    module = FakeHidModule(gamepad())
    monkeypatch.setattr(type(module.device()), "open", refuse)
    with hid_device(module) as device:
        assert device.wait_state(State.LOST, 2.0)
        assert device.counters.last_error.startswith("permission denied: HID device 046d:c21d is plugged in")
        assert "udev rule" in device.counters.last_error


def test_the_real_hidapi_module_is_used_by_default_and_a_missing_device_is_lost_not_fatal():
    device = fast(open_device("hid://dead:beef"))
    assert isinstance(device, HidDevice)
    with device:
        assert device.wait_state(State.LOST, 2.0)
        assert device.counters.last_error == "not plugged in: no HID device dead:beef plugged in"
