"""Wire twins: logged readings re-encoded onto each backend's wire (a real pty read by pyserial, fake
HID hardware, a python-can virtual bus, real mido Messages, real UDP) come back bit for bit from the
real adapters; what a wire cannot carry, and URLs with no wire, fail with a clear DeviceError; and
closing a twin releases everything."""

from __future__ import annotations

import math
import random
import struct
import threading
import time

import mido
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from devices import DeviceError, State, Url, open_twin
from devices.can_device import CanDevice
from devices.hid_descriptor import ReportLayout
from devices.hid_device import HidDevice
from devices.midi_device import MidiDevice
from devices.simulated_can import AXES_ID, EXTRA_ID, JOYSTICK_DBC, JOYSTICK_SIGNALS, joystick_database
from devices.simulated_hid import GAMEPAD_DESCRIPTOR, FakeHidModule, gamepad, gamepad_report, knobs_report
from devices.twin import differences

EXAMPLES = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
NAMES = st.text(st.sampled_from("abcdefghijklmnopqrstuvwxyz_0123456789"), min_size=1, max_size=8)
FINITE = st.floats(allow_nan=False, allow_infinity=False)


def bits(values: dict) -> dict:
    """The values as their IEEE bits: equal only when bit-exact (-0.0 differs from 0.0)."""
    return {k: struct.pack("<d", v) for k, v in values.items()}


def round_trip(twin, values: dict) -> None:
    got = twin.exchange(values)
    assert got.device == twin.device.name
    assert bits(got.values) == bits(values)


@pytest.fixture(scope="module")
def twins():
    """Twins opened once for the module (a pty and a reader thread each), closed at its end."""
    opened = {}

    def get(url: str, wire_info: dict | None = None):
        if (url, str(wire_info)) not in opened:
            opened[url, str(wire_info)] = open_twin(url, "dev", wire_info)
        return opened[url, str(wire_info)]

    yield get
    for twin in opened.values():
        twin.close()


# -- serial and sim://joystick ----------------------------------------------------------------------

@EXAMPLES
@given(st.dictionaries(NAMES, FINITE, min_size=1, max_size=8))
def test_ascii_carries_any_finite_float_by_name(twins, values):
    round_trip(twins("serial:///dev/ttyACM0?protocol=ascii&baudrate=9600"), values)
    round_trip(twins("serial:///dev/ttyACM0?protocol=ascii&checksum=nmea"), values)


@EXAMPLES
@given(st.lists(st.integers(-32768, 32767), min_size=1, max_size=16), st.sampled_from(["cobs", "slip"]))
def test_i16_frames_carry_integers_positionally(twins, raw, protocol):
    values = {f"ch{i}": float(v) for i, v in enumerate(raw)}
    round_trip(twins(f"serial:///dev/ttyUSB0?protocol={protocol}&format=i16"), values)


@EXAMPLES
@given(st.lists(st.floats(width=32, allow_nan=False, allow_infinity=False), min_size=3, max_size=3),
       st.sampled_from(["cobs", "slip"]))
def test_f32_frames_carry_float32_values_by_channel_name(twins, floats, protocol):
    values = dict(zip(["yaw", "pitch", "roll"], floats))
    round_trip(twins(f"serial:///dev/ttyACM0?protocol={protocol}&format=f32&channels=yaw,pitch,roll"), values)


@pytest.mark.parametrize("query", ["protocol=ascii&channels=6&rate=200", "protocol=ascii&channels=3&checksum=nmea",
                                   "protocol=cobs&format=f32&channels=a,b&style=csv",
                                   "protocol=slip&channels=2"])
def test_sim_joystick_twins_read_through_the_simulated_device(twins, query):
    twin = twins(f"sim://joystick?{query}")
    names = twin.device.channels
    rng = random.Random(1)
    for i in range(200):
        extremes = [-32768.0, 32767.0, 0.0, 1023.0][i % 4]
        raw = [float(rng.randint(-32768, 32767)) if i % 5 else extremes for _ in names]
        round_trip(twin, dict(zip(names, raw)))


@pytest.mark.parametrize(("url", "values", "why"), [
    ("serial:///dev/x?protocol=cobs", {"ch0": 1.5}, "channel 'ch0': sent 1.5, got 2.0"),
    ("serial:///dev/x?protocol=slip", {"ch0": 40000.0}, "cannot carry"),
    ("serial:///dev/x?protocol=cobs&format=f32", {"ch0": 0.1}, "channel 'ch0': sent 0.1, got 0.10000000149"),
    ("serial:///dev/x?protocol=cobs&format=f32", {"ch0": 1e300}, "cannot carry"),
    ("serial:///dev/x?protocol=cobs&channels=a,b", {"a": 1.0}, "cannot carry"),
    ("serial:///dev/x?protocol=ascii", {"ch0": math.nan}, "bad frame"),
    ("serial:///dev/x?protocol=ascii", {"ch0": math.inf}, "bad frame"),
])
def test_what_a_serial_wire_cannot_carry_is_a_clear_error(twins, url, values, why):
    with pytest.raises(DeviceError, match="dev: .*" + why.replace("(", r"\(").replace(".", r"\.")):
        twins(url).exchange(values)


# -- HID ----------------------------------------------------------------------------------------------

LAYOUT = ReportLayout.from_descriptor(GAMEPAD_DESCRIPTOR)
GAMEPAD_INFO = {"report_descriptor": GAMEPAD_DESCRIPTOR.hex()}


@EXAMPLES
@given(st.binary(min_size=13, max_size=13), st.binary(min_size=3, max_size=3))
def test_hid_readings_any_report_decodes_to_come_back_exactly(twins, pads, knobs):
    """Realistic values: whatever the adapter's decoding makes of any report (sticks at their
    extremes, buttons 0/1, the hat centred at -1 or in 45-degree steps, 10-bit knobs)."""
    twin = twins("hid://046d:c21d", GAMEPAD_INFO)
    round_trip(twin, LAYOUT.decode(bytes([1]) + pads))
    round_trip(twin, LAYOUT.decode(bytes([2]) + knobs))


def test_hid_extremes_and_raw_values(twins):
    twin = twins("hid://046d:c21d", GAMEPAD_INFO)
    for report in (gamepad_report(-32768, 32767, 0, -1, 255, 0, 0xFFF, 7), gamepad_report(hat=15),
                   knobs_report(1023, 0)):
        round_trip(twin, LAYOUT.decode(report))
    raw = twins("hid://046d:c21d?raw=1", GAMEPAD_INFO)
    round_trip(raw, ReportLayout.from_descriptor(GAMEPAD_DESCRIPTOR, raw=True).decode(
        gamepad_report(x=-32768, y=12345, z=200, buttons=0b101, hat=3)))


def test_hid_wire_info_from_a_device_that_read_its_descriptor_rebuilds_it():
    device = HidDevice.from_url(Url.parse("hid://046d:c21d:PAD7?usage_page=1"), "pad",
                                hid_module=FakeHidModule(gamepad(serial="PAD7")))
    assert device.wire_info() == {}
    with device:
        assert device.wait_state(State.OPEN)
        info = device.wire_info()
    assert info == GAMEPAD_INFO
    with open_twin("hid://046d:c21d:PAD7?usage_page=1", "pad", info) as twin:
        round_trip(twin, LAYOUT.decode(gamepad_report(x=100, buttons=2, hat=8)))


def test_hid_fields_by_hand_travel_in_wire_info():
    fields = [{"name": "knob", "bit_offset": 0, "bit_size": 10}, {"name": "push", "bit_offset": 10, "bit_size": 1}]
    url = "hid://16c0:05df"
    device = HidDevice.from_url(Url.parse(url), "box", fields=fields, hid_module=FakeHidModule())
    info = device.wire_info()
    with open_twin(url, "box", info) as twin:
        for k in range(0, 1024, 7):
            round_trip(twin, {"knob": k * (1 / 1023), "push": float(k % 2)})  # as the adapter scales
    with open_twin(url + "?fields=knob:0:8;push:8:1", "box", {}) as twin:
        round_trip(twin, {"knob": 1.0, "push": 1.0})


def test_what_a_hid_wire_cannot_carry_is_a_clear_error(twins):
    twin = twins("hid://046d:c21d", GAMEPAD_INFO)
    values = LAYOUT.decode(gamepad_report())
    with pytest.raises(DeviceError, match=r"channel 'X': sent 0\.3, got 0\.29999"):
        twin.exchange({**values, "X": 0.3})
    with pytest.raises(DeviceError, match="cannot carry .*no input report"):
        twin.exchange({"X": 0.0})
    with pytest.raises(DeviceError, match="pad: .*no HID report descriptor"):
        open_twin("hid://046d:c21d", "pad", {})


# -- CAN ----------------------------------------------------------------------------------------------

DB = joystick_database()


def _joystick_readings(seed: int, n: int):
    """Readings as the joystick's frames decode (cantools, independently of the rig's decoder)."""
    rng = random.Random(seed)
    for i in range(n):
        frame_id, size = (AXES_ID, 8) if i % 2 else (EXTRA_ID, 4)
        data = bytes(rng.choice([0, 0xFF, rng.randrange(256)]) for _ in range(size))
        yield {k: float(v) for k, v in DB.decode_message(frame_id, data, decode_choices=False).items()}


def test_can_signals_by_hand_round_trip(twins):
    twin = twins("can://socketcan/can0?bitrate=500000&filter=1&signals=" + JOYSTICK_SIGNALS)
    assert twin.device.interface == "virtual" and twin.device.channel.startswith("twin-")
    for values in _joystick_readings(1, 300):
        round_trip(twin, values)


def test_can_dbc_text_in_wire_info_outlives_the_file(tmp_path):
    path = tmp_path / "joy.dbc"
    path.write_text(JOYSTICK_DBC)
    url = f"can://virtual/ch9?dbc={path}&decoder=cantools"
    info = CanDevice.from_url(Url.parse(url), "joy").wire_info()
    path.unlink()
    with open_twin(url, "joy", info) as twin:
        assert type(twin.device.decoder).__name__ == "CantoolsDecoder"
        for values in _joystick_readings(2, 200):
            round_trip(twin, values)


def test_what_a_can_wire_cannot_carry_is_a_clear_error(twins):
    twin = twins("can://virtual/x?signals=" + JOYSTICK_SIGNALS)
    values = next(_joystick_readings(3, 1))
    with pytest.raises(DeviceError, match=r"channel 'Hat': sent 99\.0, got 15\.0"):
        twin.exchange({**values, "Hat": 99.0})
    with pytest.raises(DeviceError, match="cannot carry .*no frame carries"):
        twin.exchange({"Hat": 1.0})


# -- MIDI ---------------------------------------------------------------------------------------------

MESSAGES = st.one_of(
    st.builds(lambda c, v: mido.Message("control_change", control=c, value=v),
              st.integers(0, 127), st.integers(0, 127)),
    st.builds(lambda c, m, l: [mido.Message("control_change", control=c, value=m),
                                mido.Message("control_change", control=c + 32, value=l)],
              st.sampled_from([1, 7]), st.integers(0, 127), st.integers(0, 127)),
    st.builds(lambda p: mido.Message("pitchwheel", pitch=p), st.integers(-8192, 8191)),
    st.builds(lambda n, v: mido.Message("note_on", note=n, velocity=v), st.integers(0, 127), st.integers(0, 127)),
    st.builds(lambda n: mido.Message("note_off", note=n), st.integers(0, 127)),
)


RECORDER = MidiDevice("rec", "box", cc14=[1, 7])
"""What the controller's readings were logged by (its 14-bit MSBs in step with the twin's adapter)."""


@pytest.mark.slow
@EXAMPLES
@given(st.lists(MESSAGES, min_size=1, max_size=6))
def test_midi_readings_of_a_real_message_stream_come_back_exactly(twins, stream):
    """The log a controller makes (a 14-bit knob sends its MSB, then its LSB), replayed in order."""
    twin = twins("midi://nanoKONTROL2?cc14=1,7")
    for item in stream:
        for message in item if isinstance(item, list) else [item]:
            values = RECORDER.reading(message)
            if values:
                round_trip(twin, values)


def test_midi_extremes_and_a_lone_fine_value(twins):
    twin = twins("midi://box?channel=3&cc14=7")
    for values in ({"cc7": 1.0}, {"cc7": 0.0}, {"cc7": 8193 / 16383}, {"cc7": 16382 / 16383},
                   {"cc20": 1.0}, {"cc20": 0.0}, {"pitchbend": -1.0}, {"pitchbend": 1.0},
                   {"pitchbend": 0.0}, {"note60": 1.0}, {"note60": 0.0}, {"note0": 1.0}):
        round_trip(twin, values)


def test_what_a_midi_wire_cannot_carry_is_a_clear_error(twins):
    twin = twins("midi://box")
    with pytest.raises(DeviceError, match=r"channel 'cc1': sent 0\.3, got 0\.299"):
        twin.exchange({"cc1": 0.3})
    with pytest.raises(DeviceError, match=r"channel 'note5': sent 0\.5, got 1\.0"):
        twin.exchange({"note5": 0.5})
    with pytest.raises(DeviceError, match="cannot carry .*one channel"):
        twin.exchange({"cc1": 0.0, "cc2": 0.0})
    with pytest.raises(DeviceError, match="cannot carry .*'aftertouch'"):
        twin.exchange({"aftertouch": 0.0})


# -- OSC ----------------------------------------------------------------------------------------------

OSC_NAMES = st.text(st.sampled_from("abcdefghijklmnopqrstuvwxyzABCXYZ_/0123456789"), min_size=1,
                    max_size=12).filter(lambda s: not s.startswith("/"))


@EXAMPLES
@given(st.dictionaries(OSC_NAMES, st.floats(allow_nan=False), min_size=1, max_size=52))
def test_osc_readings_come_back_exactly_as_doubles(twins, values):
    round_trip(twins("osc://127.0.0.1:39539"), values)


def test_osc_edge_names_and_extremes(twins):
    twin = twins("osc://127.0.0.1:39539")
    for values in ({"VMC/Ext/Blend/Apply": 1.0}, {"fader/1": -0.0}, {"x": 5e-324},
                   {"eyeBlinkLeft": 0.0, "jawOpen": 1.0, "mouthSmileLeft": 0.25}):
        round_trip(twin, values)


# -- the registry, errors and resources -------------------------------------------------------------------

@pytest.mark.parametrize("url", ["replay://take.jsonl", "override:face.jaw", "not a url", "gpio://pin4",
                                 "sim://not-a-joystick"])
def test_urls_with_no_wire_are_refused_naming_device_and_url(url):
    with pytest.raises(DeviceError, match=r"^faders: .*") as err:
        open_twin(url, "faders")
    assert url in str(err.value) or "sim URL" in str(err.value)


def test_a_sample_that_comes_unasked_and_one_that_never_comes(monkeypatch):
    with open_twin("serial:///dev/x?protocol=ascii", "slider") as twin:
        twin.send({"a": 1.0})  # sent without waiting: its Sample belongs to no exchange
        time.sleep(0.3)
        with pytest.raises(DeviceError, match=r"slider: .*Samples no reading was sent for: \[\{'a': 1\.0\}\]"):
            twin.exchange({"a": 2.0})
        monkeypatch.setattr(twin, "_put", lambda values: 1)  # a reading lost on the wire
        with pytest.raises(DeviceError, match=r"slider: no Sample .* within 0\.1 s of sending \{'a': 3\.0\}"):
            twin.exchange({"a": 3.0}, timeout=0.1)


def test_differences_are_bit_exact_and_name_channels():
    assert differences({"a": 0.0}, {"a": 0.0}) == ""
    assert differences({"a": -0.0}, {"a": 0.0}) == "channel 'a': sent -0.0, got 0.0"
    assert differences({"a": 1.0}, {"b": 1.0}) == "channel 'a': sent 1.0, got nothing; channel 'b': sent nothing, got 1.0"


def test_closing_twins_releases_threads_ports_and_sockets():
    start = threading.active_count()
    twins = [open_twin(url, "dev", info) for url, info in [
        ("serial:///dev/x?protocol=cobs", {}), ("sim://joystick?protocol=ascii&channels=2", {}),
        ("hid://046d:c21d", GAMEPAD_INFO), ("can://virtual/c?signals=" + JOYSTICK_SIGNALS, {}),
        ("midi://box", {}), ("osc://127.0.0.1:1", {})]]
    assert threading.active_count() == start + len(twins)
    serial, sim, _, can_twin, midi, osc = twins
    for twin in twins:
        twin.close()
    assert threading.active_count() == start
    assert all(twin.device.state == State.CLOSED for twin in twins)
    assert not serial.joystick.plugged and not sim.joystick.plugged
    assert can_twin.sender._is_shutdown and midi.port.closed and osc.sender.fileno() == -1
