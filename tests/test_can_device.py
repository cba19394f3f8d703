"""CAN: our signal decoder against cantools (Intel and Motorola numbering, signed, scaled), and
CanDevice on python-can's virtual bus reading the simulated joystick, by our decoder and by DBC."""

from __future__ import annotations

import itertools
import time
from contextlib import closing

import can
import cantools
import pytest
from cantools.database.can import Message, Signal
from cantools.database.conversion import BaseConversion
from hypothesis import given, settings
from hypothesis import strategies as st
from polling import wait_for

from devices import DeviceError, State, Url, open_device
from devices.can_device import BadFrame, CanDevice, CanSignal, SignalDecoder, load_dbc
from devices.simulated_can import AXES_ID, EXTRA_ID, JOYSTICK_DBC, JOYSTICK_SIGNALS, CanJoystick

_channels = itertools.count()


def channel() -> str:
    """A virtual bus of this test's own (virtual buses are process-wide, by channel name)."""
    return f"test-can-{next(_channels)}"


# -- our decoder against cantools ------------------------------------------------------------------

@st.composite
def signals(draw, frame_bytes: int = 8):
    """A random signal that fits a frame: either byte order, 1..64 bits, any start, signed or not,
    scaled or not."""
    bits = 8 * frame_bytes
    length = draw(st.integers(1, min(64, bits)))
    big = draw(st.booleans())
    first = draw(st.integers(0, bits - length))  # the first bit on the wire the signal takes
    if big:  # DBC start = the most significant bit, in the byte's own numbering
        start = (first // 8) * 8 + 7 - first % 8
    else:  # DBC start = the least significant bit; pick it so the signal fits
        start = first
    signed = draw(st.booleans()) and length > 1
    scale = draw(st.sampled_from([1, 2, 0.5, 0.1, 1 / 3, -0.25, 1e-3]))
    offset = draw(st.sampled_from([0, 1, -40, 0.5, 273.15]))
    return Signal(f"s{draw(st.integers(0, 10**6))}", start, length, "big_endian" if big else "little_endian",
                  signed, conversion=BaseConversion.factory(scale=scale, offset=offset))


def ours(signal: Signal, frame_id: int = 0x123, lengths=None) -> SignalDecoder:
    return SignalDecoder([CanSignal.from_cantools(signal, frame_id)], lengths)


@settings(max_examples=300, deadline=None)
@given(signals(), st.data())
def test_a_value_encoded_by_cantools_is_decoded_by_ours_as_by_cantools(signal, data):
    lo = -(1 << (signal.length - 1)) if signal.is_signed else 0
    hi = (1 << (signal.length - 1)) - 1 if signal.is_signed else (1 << signal.length) - 1
    raw = data.draw(st.integers(lo, hi))
    message = Message(0x123, "M", 8, [signal], strict=False)
    frame = message.encode({signal.name: raw}, scaling=False, strict=False)
    theirs = message.decode(frame, decode_choices=False)[signal.name]
    mine = ours(signal, lengths={0x123: 8}).decode(0x123, frame)[signal.name]
    assert mine == float(theirs)
    assert mine == float(raw * signal.scale + signal.offset)


@settings(max_examples=200, deadline=None)
@given(st.lists(signals(frame_bytes=64), min_size=1, max_size=6), st.binary(min_size=64, max_size=64))
def test_any_bytes_decode_as_cantools_decodes_them_several_signals_a_frame(sigs, frame):
    sigs = [Signal(f"s{k}", s.start, s.length, s.byte_order, s.is_signed, conversion=s.conversion)
            for k, s in enumerate(sigs)]
    theirs = {}
    for s in sigs:  # one message each: cantools cannot unpack overlapping signals, ours can
        message = Message(0x7F0, "M", 64, [s], strict=False, is_fd=True)
        theirs.update({k: float(v) for k, v in message.decode(frame, decode_choices=False).items()})
    decoder = SignalDecoder([CanSignal.from_cantools(s, 0x7F0) for s in sigs])
    assert decoder.decode(0x7F0, frame) == theirs
    assert decoder.decode(0x7F0, frame + b"\xff" * 3) == theirs  # longer frames: the rest unread
    assert decoder.decode(0x7F1, frame) is None  # not our id


def test_short_frames_are_bad_and_the_dbc_length_counts():
    x = CanSignal.parse("x:0x10:0:8")
    motorola = CanSignal.parse("m:0x11:7:12:be:s")  # byte 0 and the high half of byte 1
    decoder = SignalDecoder([x, motorola], {0x10: 4})
    assert (x.min_bytes, motorola.min_bytes) == (1, 2)
    assert decoder.decode(0x10, b"\x05\x00\x00\x00") == {"x": 5.0}
    with pytest.raises(BadFrame, match="3 data bytes, its signals need 4"):
        decoder.decode(0x10, b"\x05\x00\x00")
    assert decoder.decode(0x11, b"\x80\x10") == {"m": float(-2048 + 1)}
    with pytest.raises(BadFrame):
        decoder.decode(0x11, b"\x80")


def test_signal_specs_by_text_and_by_mapping():
    s = CanSignal.parse("Wheel:0x101:3:12:motorola:s:0.5:-1")
    assert s == CanSignal("Wheel", 0x101, 3, 12, "big_endian", True, 0.5, -1)
    assert CanSignal.parse("b:256:56:1") == CanSignal("b", 256, 56, 1)
    device = CanDevice("m", "virtual", "x", signals=[{"name": "X", "id": "0x100", "start": 0, "length": 16,
                                                      "byte_order": "intel", "signed": True}])
    assert device.decoder.signals == [CanSignal("X", 0x100, 0, 16, "little_endian", True)]
    for bad in ("x:1:2", "x:1:0:8:sideways", "x:1:0:8:le:maybe", "x:1:0:8:le:s:abc", "x:1:0:0"):
        with pytest.raises(ValueError):
            CanSignal.parse(bad)
    with pytest.raises(ValueError, match="runs past 64 bytes"):
        CanSignal("x", 1, 500, 16)


def test_the_joystick_signals_by_hand_are_the_dbc_signals():
    db = cantools.database.load_string(JOYSTICK_DBC, "dbc")
    by_hand = {s.name: s for s in map(CanSignal.parse, JOYSTICK_SIGNALS.split(";"))}
    from_dbc = {s.name: CanSignal.from_cantools(s, m.frame_id) for m in db.messages for s in m.signals}
    assert by_hand == from_dbc


# -- CanDevice on the virtual bus --------------------------------------------------------------------

def can_device(url: str) -> CanDevice:
    device = CanDevice.from_url(Url.parse(url), "joystick")
    device.BACKOFF = (0.01, 0.05)
    return device


def read_ticks(device: CanDevice, joystick: CanJoystick, ticks: int) -> list[tuple[dict, dict]]:
    """Send ``ticks`` ticks one at a time; (sent, received) value pairs, the two frames merged."""
    out = []
    for i in range(ticks):
        sent = joystick.tick(0.37 * i)
        got = {}
        for sample in device.samples(timeout=2.0):
            got.update(sample.values)
            if len(got) == len(sent):
                break
        out.append((sent, got))
    return out


@pytest.mark.parametrize("how", ["signals", "dbc-own", "dbc-cantools"])
def test_the_device_reads_the_joystick(how, tmp_path):
    ch = channel()
    if how == "signals":
        query = f"signals={JOYSTICK_SIGNALS}"
    else:
        dbc = tmp_path / "joystick.dbc"
        dbc.write_text(JOYSTICK_DBC)
        query = f"dbc={dbc}&decoder={how.split('-')[1]}"
    device = can_device(f"can://virtual/{ch}?{query}")
    assert type(device.decoder).__name__ == ("CantoolsDecoder" if how == "dbc-cantools" else "SignalDecoder")
    with device, closing(CanJoystick(ch)) as joystick:  # ticked by hand, no thread
        assert device.wait_state(State.OPEN, 2.0)
        pairs = read_ticks(device, joystick, 12)
    for sent, got in pairs:
        assert got == sent
    assert {"JoystickX", "JoystickY", "JoystickTwist", "Throttle", "Trigger", "ThumbButton", "Hat", "Wheel",
            "Pedal"} <= set(pairs[0][1])
    assert len({p[1]["Hat"] for p in pairs}) > 3 and device.counters.bad_frames == 0


def test_the_joystick_at_a_rate_through_open_device(tmp_path):
    ch = channel()
    dbc = tmp_path / "joystick.dbc"
    dbc.write_text(JOYSTICK_DBC)
    device = open_device(f"can://virtual/{ch}?dbc={dbc}&bitrate=500000", name="joy")
    assert isinstance(device, CanDevice) and device.bus_kwargs == {"bitrate": 500000}
    with device:
        assert device.wait_state(State.OPEN, 2.0)
        with CanJoystick(ch, rate=200):
            assert wait_for(lambda: device.counters.samples >= 20)
    samples = device.drain()
    assert all(-100.0 <= s.values.get("JoystickX", 0.0) <= 100.0 for s in samples)
    assert {"JoystickX", "Throttle", "Trigger", "Hat"} <= {k for s in samples for k in s.values}


def test_every_frame_of_a_burst_becomes_a_sample_in_order():
    ch = channel()
    ticks = 3 * CanDevice.BATCH + 5  # several batches
    with can_device(f"can://virtual/{ch}?signals={JOYSTICK_SIGNALS}") as device, \
            closing(CanJoystick(ch)) as joystick:
        assert device.wait_state(State.OPEN, 2.0)
        joystick.burst(ticks)
        assert wait_for(lambda: device.counters.samples >= 2 * ticks)
        time.sleep(0.05)
        samples = device.drain()
    assert len(samples) == 2 * ticks == device.counters.samples
    assert [s.values["Counter"] for s in samples[::2]] == [float(i & 0xF) for i in range(ticks)]


def test_bad_dlc_error_frames_and_foreign_ids():
    ch = channel()
    with can_device(f"can://virtual/{ch}?signals={JOYSTICK_SIGNALS}") as device, closing(CanJoystick(ch)) as joystick:
        assert device.wait_state(State.OPEN, 2.0)
        joystick.send_raw(AXES_ID, b"\x01\x02")            # a short frame: bad
        joystick.send_raw(EXTRA_ID, b"")                    # empty: bad
        joystick.send_raw(0x555, bytes(8))                  # someone else's frame: ignored
        joystick.bus.send(can.Message(is_error_frame=True))  # an error frame: bad
        joystick.send_raw(EXTRA_ID, b"\x20\x00\x00\x00")    # Hat 2
        assert next(device.samples(timeout=2.0)).values["Hat"] == 2.0
        assert device.counters.bad_frames == 3 and device.ignored_frames == 1
        assert "2 data bytes" in device.counters.last_error or "0 data bytes" in device.counters.last_error


def test_filters_keep_foreign_ids_out():
    ch = channel()
    with can_device(f"can://virtual/{ch}?signals=Hat:{EXTRA_ID}:7:4:be&filter=1") as device, \
            closing(CanJoystick(ch)) as joystick:
        assert device.wait_state(State.OPEN, 2.0)
        joystick.send_raw(0x555, bytes(8))
        joystick.send_raw(AXES_ID, bytes(8))
        joystick.send_raw(EXTRA_ID, b"\x30")
        assert next(device.samples(timeout=2.0)).values == {"Hat": 3.0}
        assert device.ignored_frames == 0


def test_close_is_prompt():
    device = can_device(f"can://virtual/{channel()}?signals=x:1:0:8").start()
    assert device.wait_state(State.OPEN, 2.0)
    time.sleep(0.05)  # inside recv(timeout) now
    start = time.monotonic()
    device.close()
    assert time.monotonic() - start < 0.5
    assert device.state == State.CLOSED and device.bus is None


def test_a_bus_that_cannot_be_opened_is_lost_not_fatal():
    with can_device("can://socketcan/nosuchcan0?signals=x:1:0:8") as device:
        assert device.wait_state(State.LOST, 2.0)
        assert "cannot open socketcan bus 'nosuchcan0'" in device.counters.last_error


@pytest.mark.parametrize("url, message", [
    ("can:///ch0?signals=x:1:0:8", "expected can://<interface>/<channel>"),
    ("can://nosuchiface/ch0?signals=x:1:0:8", "unknown python-can interface"),
    ("can://virtual/ch0", "needs its signals"),
    ("can://virtual/ch0?signals=x:1:0:8&dbc=a.dbc", "needs its signals"),
    ("can://virtual/ch0?signals=x:1:0", "expected NAME:ID:START:LENGTH"),
    ("can://virtual/ch0?dbc=/no/such.dbc", "No such file"),
    ("can://virtual/ch0?signals=x:1:0:8&decoder=fast", "decoder 'fast'"),
    ("can://virtual/ch0?signals=x:1:0:8&timeout_ms=soon", "timeout_ms"),
])
def test_bad_urls_say_what_was_expected(url, message):
    with pytest.raises(DeviceError, match=message):
        CanDevice.from_url(Url.parse(url), "x")


def test_dbc_names_shared_by_two_messages_get_the_message_name(tmp_path):
    dbc = tmp_path / "two.dbc"
    dbc.write_text('VERSION ""\n\nBS_:\n\nBU_: A\n\n'
                   'BO_ 16 Left: 1 A\n SG_ Pos : 0|8@1+ (1,0) [0|255] "" A\n\n'
                   'BO_ 17 Right: 2 A\n SG_ Pos : 0|8@1+ (1,0) [0|255] "" A\n SG_ Extra : 8|1@1+ (1,0) [0|1] "" A\n')
    for decoder in ("own", "cantools"):
        d = load_dbc(str(dbc), decoder)
        assert d.decode(16, b"\x07") == {"Left.Pos": 7.0}
        assert d.decode(17, b"\x07\x01") == {"Right.Pos": 7.0, "Extra": 1.0}
        with pytest.raises(BadFrame):
            d.decode(17, b"\x07")  # the DBC says 2 bytes
