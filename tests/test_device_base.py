"""The Device base class: a reader thread, a bounded queue, reconnection with backoff, URLs."""

from __future__ import annotations

import errno
import os
import threading
import time

import pytest

from devices import BACKENDS, DeviceError, device_class, open_device
from devices.base import Device, DeviceLost, State, Url, lost_reason


class Scripted(Device):
    """A device whose 'hardware' is a list of readings and a plug the test pulls."""

    BACKOFF = (0.01, 0.05)

    @classmethod
    def from_url(cls, url, name):
        return cls()

    def __init__(self, readings=(), queue=None) -> None:
        if queue is not None:
            self.QUEUE = queue
        super().__init__("scripted")
        self.readings = list(readings)
        self.plugged = threading.Event()
        self.plugged.set()
        self.opens = 0

    def _open(self) -> None:
        if not self.plugged.is_set():
            raise FileNotFoundError("no such device")
        self.opens += 1

    def _read(self):
        if not self.plugged.is_set():
            raise DeviceLost("unplugged")
        if self.readings:
            return [self.readings.pop(0)]
        time.sleep(0.002)
        return []

    def _close(self) -> None:
        pass


def test_samples_arrive_in_order_with_monotonic_timestamps():
    with Scripted([{"x": float(i)} for i in range(50)]) as device:
        got = []
        for sample in device.samples(timeout=1.0):
            got.append(sample)
            if len(got) == 50:
                break
    assert [s.values["x"] for s in got] == list(range(50))
    assert all(a.t_ns <= b.t_ns for a, b in zip(got, got[1:]))
    assert {s.device for s in got} == {"scripted"}


def test_the_queue_never_grows_past_its_bound_and_counts_what_it_drops():
    device = Scripted([{"x": float(i)} for i in range(100)], queue=10)
    with device:
        deadline = time.monotonic() + 2
        while device.counters.samples < 100 and time.monotonic() < deadline:
            time.sleep(0.005)
        kept = device.drain()
    assert len(kept) == 10
    assert [s.values["x"] for s in kept] == list(range(90, 100))
    assert device.counters.dropped == 90


def test_an_unplugged_device_is_lost_then_reopened_when_plugged_back():
    device = Scripted()
    with device:
        assert device.wait_state(State.OPEN, 1.0)
        device.plugged.clear()
        assert device.wait_state(State.LOST, 1.0)
        time.sleep(0.1)
        assert device.state in (State.LOST, State.OPENING), "it must not claim to be open while unplugged"
        device.plugged.set()
        assert device.wait_state(State.OPEN, 1.0)
        device.readings.append({"x": 1.0})
        assert next(device.samples(timeout=1.0)).values == {"x": 1.0}
    assert device.counters.reconnects == 1
    assert device.opens == 2
    assert device.counters.last_error == "no such device"


def test_close_is_prompt_and_final():
    device = Scripted().start()
    assert device.wait_state(State.OPEN, 1.0)
    start = time.monotonic()
    device.close()
    assert time.monotonic() - start < 0.5
    assert device.state == State.CLOSED


def test_urls_name_a_backend_and_unknown_ones_say_which_exist():
    url = Url.parse("serial:///dev/ttyACM0?baudrate=115200&protocol=ascii")
    assert (url.scheme, url.target, url.options) == ("serial", "/dev/ttyACM0", {"baudrate": "115200", "protocol": "ascii"})
    assert Url.parse("hid://046d:c21d").target == "046d:c21d"
    with pytest.raises(DeviceError, match="expected scheme://target"):
        Url.parse("/dev/ttyACM0")
    with pytest.raises(DeviceError, match=r"unknown scheme 'foo'; known: \["):
        open_device("foo://bar")
    assert all(module.startswith("devices.") and device_class(scheme, "test").from_url for scheme, module in BACKENDS.items())


def test_an_adapter_bug_in_read_does_not_end_the_thread():
    class Flaky(Scripted):
        fail = True

        def _read(self):
            if self.fail:
                self.fail = False
                raise ValueError("adapter bug")
            return super()._read()

    with Flaky([{"x": 1.0}]) as device:
        assert next(device.samples(timeout=1.0)).values == {"x": 1.0}
    assert device.counters.reconnects == 1 and device.counters.last_error == "adapter bug"


def test_a_device_that_fails_every_read_backs_off_instead_of_spinning():
    class Broken(Scripted):
        def _read(self):
            raise ValueError("always")

    with Broken() as device:
        time.sleep(0.3)
    assert 2 <= device.counters.reconnects <= 10, device.counters.reconnects


def test_an_open_or_close_that_raises_something_odd_keeps_the_thread_alive():
    class Odd(Scripted):
        opened = False

        def _open(self):
            if not self.opened:
                self.opened = True
                raise OverflowError("port out of range")

        def _close(self):
            raise RuntimeError("close failed")

    with Odd([{"x": 2.0}]) as device:
        assert next(device.samples(timeout=1.0)).values == {"x": 2.0}


def test_every_device_error_derives_from_device_error_and_keeps_its_builtin_base(tmp_path):
    from devices.can_device import BadFrame
    from devices.hid_descriptor import DescriptorError, parse_descriptor
    from devices.samplelines import SampleLogError
    from puppet.io.samplelog import read_take_log

    for cls, builtin in ((DeviceLost, OSError), (DescriptorError, ValueError), (BadFrame, ValueError),
                         (SampleLogError, ValueError)):
        assert issubclass(cls, DeviceError) and issubclass(cls, builtin)
    # what the existing except clauses meant to catch, they still catch
    with pytest.raises(ValueError):
        parse_descriptor(b"\xc0")  # End Collection without Collection
    log = tmp_path / "samples.jsonl"
    log.write_text('{"t_ns": 1, "device": "box", "values": {"ch0": "loud"}}\n')
    with pytest.raises(DeviceError, match=r"samples.jsonl:1: expected numbers"):
        list(read_take_log(log))
    log.write_text('{"t_ns": 1, "device": "box", "values": {"ch0": 1' + "0" * 400 + '}}\n')
    with pytest.raises(ValueError, match=r"samples.jsonl:1: expected numbers"):
        list(read_take_log(log))


@pytest.mark.parametrize("code, reason", [(errno.ENOENT, "port missing"), (errno.EACCES, "permission denied"),
                                          (errno.EBUSY, "busy (another program has it open)")])
def test_a_lost_device_says_why_in_plain_words_then_the_adapters(code, reason):
    import serial  # pyserial's own failure to open a port, as serialposix raises it

    error = serial.SerialException(code, f"could not open port /dev/ttyACM0: [Errno {code}] {os.strerror(code)}")
    assert lost_reason(error) == f"{reason}: could not open port /dev/ttyACM0: [Errno {code}] {os.strerror(code)}"


def test_a_device_lost_while_open_was_unplugged():
    assert lost_reason(DeviceLost("/dev/ttyACM0: device reports readiness to read but returned no data")) == (
        "unplugged: /dev/ttyACM0: device reports readiness to read but returned no data")
    assert lost_reason(ValueError("adapter bug")) == "adapter bug"
