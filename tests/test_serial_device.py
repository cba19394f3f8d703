"""Serial devices through the real pyserial: ascii lines, COBS and SLIP frames over pseudo-terminals
and loop://, garbage and resynchronisation, unplug and replug, prompt close; property tests of the
frame parsers."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from polling import wait_for

from devices import DeviceError, State, device_class, open_device
from devices.serial_port import SerialDevice
from devices.serial_wire import (
    MAX_FRAME,
    cobs_decode,
    cobs_encode,
    crc16,
    encode_ascii_line,
    encode_cobs_frame,
    encode_payload,
    encode_slip_frame,
    make_parser,
    slip_decode,
    slip_encode,
)
from devices.simulated_serial import PtyJoystick

FRAMED = {"cobs": (encode_cobs_frame, b"\x00"), "slip": (encode_slip_frame, b"\xc0")}
FAST_BACKOFF = (0.01, 0.05)


def serial_device(url: str) -> SerialDevice:
    device = open_device(url)
    device.BACKOFF = FAST_BACKOFF
    return device


def collect(device, n: int, timeout: float = 2.0) -> list:
    """The next n Samples (fewer only if none came for ``timeout`` seconds)."""
    got = []
    for sample in device.samples(timeout=timeout):
        got.append(sample)
        if len(got) >= n:
            break
    return got


@pytest.fixture
def joystick():
    """A scripted pty joystick (no thread: the test sends)."""
    stick = PtyJoystick("ascii", rate=None)
    stick.start()
    yield stick
    stick.close()


def opened(url: str) -> SerialDevice:
    device = serial_device(url).start()
    assert device.wait_state(State.OPEN, 3), device.counters.last_error
    return device


# -- wire formats ---------------------------------------------------------------------------

def test_crc_is_ccitt_false_and_a_frame_checks_to_zero():
    assert crc16(b"123456789") == 0x29B1
    payload = encode_payload([1, -2, 300])
    assert payload[:7] == struct.pack("<B3h", 3, 1, -2, 300)
    assert crc16(payload[:-2]) == int.from_bytes(payload[-2:], "big")
    assert crc16(payload) == 0
    f32 = encode_payload([0.5, -1.25], "f32")
    assert f32[:9] == struct.pack("<B2f", 2, 0.5, -1.25) and len(f32) == 11


@pytest.mark.parametrize("raw, encoded", [
    (b"", b"\x01"), (b"\x00", b"\x01\x01"), (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"), (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255))),
    (bytes(range(255)), b"\x01\xff" + bytes(range(1, 255))),
    (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01"),
])
def test_cobs_matches_the_reference_vectors(raw, encoded):
    assert cobs_encode(raw) == encoded
    assert cobs_decode(encoded) == raw


def test_slip_escapes_and_refuses_bad_escapes():
    assert slip_encode(b"\x01\xc0\xdb\x02") == b"\x01\xdb\xdc\xdb\xdd\x02"
    assert slip_decode(b"\x01\xdb\xdc\xdb\xdd\x02") == b"\x01\xc0\xdb\x02"
    assert slip_decode(b"\xdb\xdd\xdc") == b"\xdb\xdc"
    for bad in (b"\x01\xdb", b"\xdb\x01", b"\xdb\xdb\xdc"):
        assert slip_decode(bad) is None
    assert encode_slip_frame([1]).startswith(b"\xc0") and encode_slip_frame([1]).endswith(b"\xc0")
    assert encode_cobs_frame([1]).startswith(b"\x00") and encode_cobs_frame([1]).endswith(b"\x00")


# -- ascii ----------------------------------------------------------------------------------

def test_ascii_parser_forms_line_ends_and_partial_lines():
    parser = make_parser("ascii")
    assert parser.feed(b"1,2,3\r\n4 5\t6\r7;8\n") == [
        {"ch0": 1.0, "ch1": 2.0, "ch2": 3.0}, {"ch0": 4.0, "ch1": 5.0, "ch2": 6.0}, {"ch0": 7.0, "ch1": 8.0}]
    assert parser.feed(b"-1.5, 2e3") == []
    assert parser.feed(b",+3\r") == [{"ch0": -1.5, "ch1": 2000.0, "ch2": 3.0}]
    assert parser.feed(b"\nslider1=512 slider2=300\n") == [{"slider1": 512.0, "slider2": 300.0}]
    assert parser.feed(b"a:1,b:2\r\nx = 3, y = 4\n\n  \n") == [{"a": 1.0, "b": 2.0}, {"x": 3.0, "y": 4.0}]
    assert parser.bad == 0


def test_ascii_parser_counts_and_skips_malformed_lines():
    parser = make_parser("ascii", names=["a", "b", "c"])
    good = parser.feed(b"Ready!\n1,x,3\n1,2\n1,2,3,4\nnan,1,2\na=1 a=2\na=1 d=2\na=1 2\n1_0,2,3\n"
                       b"\xff\xfe\n4,5,6\na=7 c=9\n")
    assert good == [{"a": 4.0, "b": 5.0, "c": 6.0}, {"a": 7.0, "c": 9.0}]
    assert parser.bad == 10
    parser.bad = 0
    assert parser.feed(b"9" * 5000) == [] and parser.bad == 1       # overlong: counted once ...
    assert parser.feed(b"9" * 5000 + b"\n1,2,3\n") == [{"a": 1.0, "b": 2.0, "c": 3.0}]  # ... then resync
    assert parser.bad == 1


def test_ascii_lines_over_a_pty_keep_values_names_and_monotonic_timestamps(joystick):
    device = opened(f"serial://{joystick.path}?protocol=ascii")
    try:
        before = time.monotonic_ns()
        rows = [[i, 1023 - i, i * 0.5] for i in range(40)]
        for row in rows:
            joystick.send(row)
        samples = collect(device, 40)
        after = time.monotonic_ns()
    finally:
        device.close()
    assert [list(s.values.values()) for s in samples] == [[float(v) for v in row] for row in rows]
    assert all(list(s.values) == ["ch0", "ch1", "ch2"] for s in samples)
    stamps = [s.t_ns for s in samples]
    assert stamps == sorted(stamps) and before <= stamps[0] and stamps[-1] <= after
    assert device.counters.bad_frames == 0


def test_ascii_over_a_pty_names_channels_joins_partial_lines_and_skips_bad_ones(joystick):
    device = opened(f"serial://{joystick.path}?protocol=ascii&channels=pitch,yaw")
    try:
        joystick.write(b"10,2")
        time.sleep(0.05)                     # the line arrives in two reads
        joystick.write(b"0\r\nhello\r\n1,2,3\r\npitch=5 yaw=-6\n")
        joystick.write(b"pitch=1,roll=2\n7\t8\r")
        samples = collect(device, 3)
    finally:
        device.close()
    assert [s.values for s in samples] == [{"pitch": 10.0, "yaw": 20.0}, {"pitch": 5.0, "yaw": -6.0},
                                           {"pitch": 7.0, "yaw": 8.0}]
    assert device.counters.bad_frames == 3


def test_plain_ascii_reads_noise_as_values_and_the_nmea_checksum_refuses_it():
    good = encode_ascii_line([512, 300])
    cut, flipped = b"51\n", b"513,300\n"                   # a line cut short, a digit flipped
    assert make_parser("ascii").feed(good + cut + flipped) == [
        {"ch0": 512.0, "ch1": 300.0}, {"ch0": 51.0}, {"ch0": 513.0, "ch1": 300.0}]
    line = encode_ascii_line([512, 300], checksum="nmea")
    assert line == b"512,300*29\r\n" and 0x29 == ord("5") ^ ord("1") ^ ord("2") ^ ord(",") ^ 0x33 ^ 0x30 ^ 0x30
    parser = make_parser("ascii", checksum="nmea")
    noisy = [line[:3] + b"\n", line.replace(b"512", b"513"), b"512,300\n", b"512,300*2G\n", line[:-4] + b"\n"]
    got = parser.feed(line + b"".join(noisy) + b"$" + line + b"a=1,b=2*" + b"%02X" % (0x61 ^ 0x3D ^ 0x31 ^ 0x2C
                                                                                     ^ 0x62 ^ 0x3D ^ 0x32) + b"\n")
    assert got == [{"ch0": 512.0, "ch1": 300.0}] * 2 + [{"a": 1.0, "b": 2.0}]
    assert parser.bad == parser.bad_checksums == len(noisy)
    with pytest.raises(ValueError, match="ascii"):
        make_parser("cobs", checksum="nmea")


def test_every_single_bit_flip_in_a_checksummed_line_is_caught():
    line = encode_ascii_line([512, -300, 7.25], checksum="nmea")
    for i in range(len(line) - 2):                          # every byte but the line end
        for bit in range(8):
            noisy = bytearray(line)
            noisy[i] ^= 1 << bit
            if noisy[i] in b"\r\n":
                continue                                     # that splits the line: two bad lines
            parser = make_parser("ascii", checksum="nmea")
            assert parser.feed(bytes(noisy)) == [] and parser.bad_checksums == 1, (i, bit, bytes(noisy))


def test_checksummed_lines_end_to_end_over_a_pty_count_bad_lines():
    device = opened("sim://joystick?protocol=ascii&checksum=nmea&rate=0&channels=2")
    stick = device.joystick
    try:
        assert collect(device, 20) and device.counters.bad_frames == 0
        stick.write(b"12,34\n" + encode_ascii_line([1, 2], checksum="nmea").replace(b"1,", b"7,"))
        assert wait_for(lambda: device.counters.bad_checksums == 2)
        assert collect(device, 5)                          # good lines still arrive
    finally:
        device.close()
    assert device.counters.bad_frames == device.counters.bad_checksums == 2


def test_device_options_are_checked_with_the_closest_name():
    with pytest.raises(DeviceError, match="unknown option 'protocl'.*did you mean 'protocol'"):
        open_device("serial:///dev/ttyACM0?protocl=ascii")
    with pytest.raises(DeviceError, match="did you mean 'checksum'"):
        open_device("sim://joystick?checksun=nmea")
    with pytest.raises(DeviceError, match="unknown option 'speed'"):
        open_device("serial:loop://?speed=1")                 # a handler URL: pyserial's options only
    assert open_device("serial:loop://?protocol=ascii&checksum=nmea").checksum == "nmea"
    with pytest.raises(DeviceError, match="checksum"):
        open_device("serial:///dev/x?protocol=slip&checksum=nmea")


# -- binary frames --------------------------------------------------------------------------

@pytest.mark.parametrize("protocol", ["cobs", "slip"])
@pytest.mark.parametrize("fmt", ["i16", "f32"])
def test_frames_over_loop_skip_garbage_and_resync(protocol, fmt):
    encode, delimiter = FRAMED[protocol]
    rows = [[i, -i, 32767 if fmt == "i16" else 1.5, -32768 if fmt == "i16" else -0.25] for i in range(20)]
    wire = b"".join(encode(row, fmt) for row in rows[:10])
    wire += b"\x13\x37garbage" + delimiter + b"\xdb\x01more noise"        # two bad chunks
    wire += encode(rows[10], fmt)
    wire += encode(rows[11], fmt)[1:]          # a frame with only its trailing delimiter
    wire += b"".join(encode(row, fmt) for row in rows[12:])
    device = opened(f"serial:loop://?protocol={protocol}&format={fmt}")
    try:
        device.port.write(wire)
        samples = collect(device, 20)
    finally:
        device.close()
    assert [list(s.values.values()) for s in samples] == [[float(v) for v in row] for row in rows]
    assert device.counters.bad_frames == 2


@pytest.mark.parametrize("protocol", ["cobs", "slip"])
def test_frames_over_a_pty_with_names_garbage_and_corruption(protocol):
    encode, _ = FRAMED[protocol]
    stick = PtyJoystick(protocol, rate=None, channels=3).start()
    device = opened(f"serial://{stick.path}?protocol={protocol}&channels=jaw,smile,brow")
    try:
        stick.send([1, 2, 3])
        stick.write(bytes(range(256)) * 3)                    # line noise, delimiters and all
        corrupt = bytearray(encode([4, 5, 6]))
        corrupt[3] ^= 0x40
        stick.write(bytes(corrupt))                            # fails its CRC
        stick.write(encode([1, 2]))                            # well formed, but two channels
        stick.send([7, 8, 9])
        samples = collect(device, 2)
        time.sleep(0.05)
    finally:
        device.close()
        stick.close()
    assert [s.values for s in samples] == [{"jaw": 1.0, "smile": 2.0, "brow": 3.0},
                                           {"jaw": 7.0, "smile": 8.0, "brow": 9.0}]
    assert device.counters.bad_frames >= 3
    assert device.counters.samples == 2


@pytest.mark.parametrize("protocol", ["cobs", "slip"])
def test_every_single_bit_flip_in_a_frame_is_caught(protocol):
    encode, _ = FRAMED[protocol]
    frame = encode([300, -7, 1023, 0, 256, -32768])
    for bit in range(8, 8 * (len(frame) - 1)):        # every bit between the delimiters
        wire = bytearray(frame)
        wire[bit // 8] ^= 1 << (bit % 8)
        parser = make_parser(protocol)
        got = parser.feed(bytes(wire) + encode([1, 2]))
        assert got == [{"ch0": 1.0, "ch1": 2.0}], bit
        assert parser.bad >= 1


@pytest.mark.parametrize("protocol", ["cobs", "slip"])
def test_an_overlong_frame_counts_once_and_the_stream_resyncs(protocol):
    encode, _ = FRAMED[protocol]
    parser = make_parser(protocol)
    noise = bytes([0x55]) * (MAX_FRAME + 10)
    assert parser.feed(noise[:1000]) == [] and parser.feed(noise[1000:]) == []
    assert parser.bad == 1
    assert parser.feed(encode([42])) == [{"ch0": 42.0}] and parser.bad == 1
    assert parser.feed(noise + encode([43])) == [{"ch0": 43.0}] and parser.bad == 2


@pytest.mark.parametrize("protocol", ["cobs", "slip"])
def test_a_frame_without_its_leading_delimiter_is_lost_with_the_noise_before_it(protocol):
    encode, _ = FRAMED[protocol]
    parser = make_parser(protocol)
    assert parser.feed(encode([1])[1:] + encode([2])[1:]) == [{"ch0": 1.0}, {"ch0": 2.0}]
    assert parser.feed(b"noise" + encode([3])[1:] + encode([4])) == [{"ch0": 4.0}]
    assert parser.bad == 1


def test_close_is_prompt_when_idle_reading_and_lost(joystick):
    for url in (f"serial://{joystick.path}?protocol=ascii", "serial:loop://?protocol=cobs",
                "serial:///nonexistent/ttyACM9?protocol=ascii"):
        device = serial_device(url)
        device.BACKOFF = (0.05, 2.0)
        device.start()
        time.sleep(0.2)                      # open and reading, or deep in backoff
        started = time.monotonic()
        device.close()
        assert time.monotonic() - started < 0.5, url
        assert device.state == State.CLOSED


def test_a_missing_port_is_lost_not_an_error():
    device = serial_device("serial:///nonexistent/ttyACM9").start()
    try:
        assert device.wait_state(State.LOST, 2)
        assert device.counters.last_error.startswith("port missing: ") and "ttyACM9" in device.counters.last_error
    finally:
        device.close()


# -- URLs ------------------------------------------------------------------------------------

def test_urls():
    assert device_class("serial", "test") is SerialDevice
    device = open_device("serial:///dev/ttyACM0?baudrate=9600&protocol=slip&format=f32&channels=a,b")
    assert (device.port_url, device.protocol, device.fmt, device.channels) == (
        "/dev/ttyACM0", "slip", "f32", ("a", "b"))
    assert open_device("serial:/dev/ttyUSB0").protocol == "ascii"
    assert open_device("serial:loop://?protocol=cobs&logging=debug").port_url == "loop://?logging=debug"
    assert open_device("serial:socket://localhost:7777?protocol=cobs").port_url == "socket://localhost:7777"
    for bad in ("serial:///dev/ttyACM0?protocol=morse", "serial:///dev/ttyACM0?speed=9600",
                "serial:///dev/ttyACM0?baudrate=fast", "serial:nosuch://x", "serial:///dev/x?format=f32",
                "serial:///dev/x?channels=a,,b", "serial:///dev/x?timeout=5", "sim://gamepad"):
        with pytest.raises(DeviceError):
            open_device(bad)


def test_sim_url_reads_its_own_pty_joystick():
    device = open_device("sim://joystick?protocol=slip&rate=400&channels=jaw,smile")
    with device:
        samples = collect(device, 10)
    assert len(samples) == 10 and all(set(s.values) == {"jaw", "smile"} for s in samples)
    assert all(0 <= v <= 1023 for s in samples for v in s.values.values())
    assert device.counters.bad_frames == 0


def test_puppet_sim_joystick_is_a_port_whose_plug_enter_pulls(tmp_path):
    """``puppet sim joystick`` prints a URL a serial device reads its sliders at; Enter unplugs it
    (the device goes LOST), Enter again plugs it back (it reads again); terminated, it removes its
    stable path."""
    link = tmp_path / "stick"
    root = Path(__file__).resolve().parents[1]
    command = [sys.executable, "-m", "puppet.cli", "sim", "joystick", "--protocol", "cobs", "--channels", "3",
               "--link", str(link)]
    stick = subprocess.Popen(command, cwd=root, env={**os.environ, "PYTHONPATH": str(root)}, text=True,
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        shown = [stick.stdout.readline() for _ in range(4)]
        assert shown[2].split() == ["device", "URL:", f"serial://{link}?protocol=cobs"], shown
        device = serial_device(shown[2].split()[-1])
        with device:
            samples = collect(device, 20)
            assert len(samples) == 20 and all(len(s.values) == 3 for s in samples)
            assert all(0 <= v <= 1023 for s in samples for v in s.values.values())
            stick.stdin.write("\n")
            stick.stdin.flush()
            assert stick.stdout.readline().strip() == "unplugged"
            assert device.wait_state(State.LOST, 5)
            stick.stdin.write("\n")
            stick.stdin.flush()
            assert stick.stdout.readline().split()[:2] == ["plugged", "in:"]
            assert device.wait_state(State.OPEN, 5) and len(collect(device, 5)) == 5
    finally:
        stick.terminate()
        out, _ = stick.communicate(timeout=10)
    assert stick.returncode == 0 and out.startswith("sent "), out
    assert not link.is_symlink()


# -- properties of the frame parsers ---------------------------------------------------------

int16s = st.integers(-32768, 32767).map(float)
float32s = st.floats(width=32, allow_nan=False, allow_infinity=False)
PROPS = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def framed_stream(draw):
    protocol = draw(st.sampled_from(["cobs", "slip"]))
    fmt = draw(st.sampled_from(["i16", "f32"]))
    values = int16s if fmt == "i16" else float32s
    rows = draw(st.lists(st.lists(values, min_size=1, max_size=12), min_size=1, max_size=12))
    return protocol, fmt, rows


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    return [data[a:b] for a, b in zip([0, *points], [*points, len(data)])]


@PROPS
@given(framed_stream(), st.lists(st.integers(0, 10_000), max_size=30))
def test_frames_survive_any_chunking(stream, cuts):
    protocol, fmt, rows = stream
    encode, _ = FRAMED[protocol]
    wire = b"".join(encode(row, fmt) for row in rows)
    parser = make_parser(protocol, fmt=fmt)
    got = [reading for piece in chunked(wire, cuts) for reading in parser.feed(piece)]
    assert [list(r.values()) for r in got] == rows
    assert parser.bad == 0


@PROPS
@given(st.lists(st.lists(int16s, min_size=1, max_size=8), min_size=1, max_size=10),
       st.sampled_from([",", " ", "\t"]), st.sampled_from(["\r\n", "\n", "\r"]),
       st.lists(st.integers(0, 10_000), max_size=30))
def test_ascii_lines_survive_any_chunking(rows, sep, end, cuts):
    wire = b"".join(encode_ascii_line(row, sep, end) for row in rows)
    parser = make_parser("ascii")
    got = [reading for piece in chunked(wire, cuts) for reading in parser.feed(piece)]
    if end == "\r":           # a lone CR ends a line only when the next byte comes: flush it
        got += parser.feed(b"\n")
    assert [list(r.values()) for r in got] == rows
    assert parser.bad == 0


@PROPS
@given(framed_stream(), st.data())
def test_garbage_between_frames_is_skipped_and_counted_never_read(stream, data):
    protocol, fmt, rows = stream
    encode, delimiter = FRAMED[protocol]
    noise = st.binary(max_size=40) | st.lists(st.sampled_from([0x00, 0xC0, 0xDB, 0xDC, 0x01, 0xFF]),
                                              max_size=20).map(bytes)
    garbage = [data.draw(noise) for _ in range(len(rows) + 1)]
    pieces = [p for g in garbage for p in g.split(delimiter) if p]
    # the one way to read something that was not sent: noise that is itself a well-formed frame
    # with a matching CRC (odds about 1 in 65,536 per piece); such noise is not garbage.
    assume(all(make_parser(protocol, fmt=fmt).feed(delimiter + p + delimiter) == [] for p in pieces))
    wire = b"".join(g + encode(row, fmt) for g, row in zip(garbage, rows)) + garbage[-1] + delimiter
    parser = make_parser(protocol, fmt=fmt)
    cuts = data.draw(st.lists(st.integers(0, 10_000), max_size=20))
    got = [reading for piece in chunked(wire, cuts) for reading in parser.feed(piece)]
    assert [list(r.values()) for r in got] == rows
    assert parser.bad == len(pieces)
