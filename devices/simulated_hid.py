"""A fake ``hid`` module for tests and demos: HID "hardware" that plays scripted reports.

``FakeHidModule`` stands where cython-hidapi's ``hid`` module stands (``device()``,
``enumerate()``), and ``FakeHidDevice`` (what ``device()`` returns) has the methods of
``hid.device`` that the rig uses, with the same behaviour where it matters:

- ``open(vendor_id, product_id, serial_number=None)`` and ``open_path(path: bytes)`` raise
  ``OSError('open failed')`` when no such device is plugged in;
- ``read(max_length, timeout_ms=0)`` returns a list of ints, ``[]`` when nothing came within
  ``timeout_ms`` (``timeout_ms <= 0`` blocks, like ``hid_read``, unless ``set_nonblocking(1)`` was
  called, when it returns at once); it raises ``OSError('read error')`` once the hardware is
  unplugged, and keeps raising on that handle even after a replug (a real handle goes stale too);
- methods on a handle that is not open raise ``ValueError('not open')``.

The hardware is a ``FakeHidHardware``: ids, strings, a report descriptor, and a source of input
reports (a queue that ``feed()`` fills, and optionally an iterator played at ``rate`` reports per
second, or as fast as they are read when ``rate`` is None). ``unplug()`` and ``replug()`` pull and
push its plug. ``gamepad()`` makes one that looks like a USB game pad, built on
``GAMEPAD_DESCRIPTOR`` below, and ``gamepad_report()`` packs its reports.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

# A USB game pad's report descriptor, as a real one is written (HID 1.11 short items).
# Report 1: four 16-bit signed sticks, two 8-bit triggers, 12 buttons, a 4-bit hat, a pad byte.
# Report 2: two 10-bit knobs and 4 bits of padding. An output report (rumble) is declared too:
# an input parser must skip it.
GAMEPAD_DESCRIPTOR = bytes([
    0x05, 0x01,        # Usage Page (Generic Desktop)
    0x09, 0x05,        # Usage (Game Pad)
    0xA1, 0x01,        # Collection (Application)
    0x85, 0x01,        #   Report ID (1)
    0x09, 0x01,        #   Usage (Pointer)
    0xA1, 0x00,        #   Collection (Physical)
    0x09, 0x30,        #     Usage (X)
    0x09, 0x31,        #     Usage (Y)
    0x09, 0x33,        #     Usage (Rx)
    0x09, 0x34,        #     Usage (Ry)
    0x16, 0x00, 0x80,  #     Logical Minimum (-32768)
    0x26, 0xFF, 0x7F,  #     Logical Maximum (32767)
    0x75, 0x10,        #     Report Size (16)
    0x95, 0x04,        #     Report Count (4)
    0x81, 0x02,        #     Input (Data, Variable, Absolute)
    0xC0,              #   End Collection
    0x09, 0x32,        #   Usage (Z)
    0x09, 0x35,        #   Usage (Rz)
    0x15, 0x00,        #   Logical Minimum (0)
    0x26, 0xFF, 0x00,  #   Logical Maximum (255)
    0x75, 0x08,        #   Report Size (8)
    0x95, 0x02,        #   Report Count (2)
    0x81, 0x02,        #   Input (Data, Variable, Absolute)
    0x05, 0x09,        #   Usage Page (Button)
    0x19, 0x01,        #   Usage Minimum (Button 1)
    0x29, 0x0C,        #   Usage Maximum (Button 12)
    0x15, 0x00,        #   Logical Minimum (0)
    0x25, 0x01,        #   Logical Maximum (1)
    0x75, 0x01,        #   Report Size (1)
    0x95, 0x0C,        #   Report Count (12)
    0x81, 0x02,        #   Input (Data, Variable, Absolute)
    0x05, 0x01,        #   Usage Page (Generic Desktop)
    0x09, 0x39,        #   Usage (Hat switch)
    0x15, 0x00,        #   Logical Minimum (0)
    0x25, 0x07,        #   Logical Maximum (7)
    0x35, 0x00,        #   Physical Minimum (0)
    0x46, 0x3B, 0x01,  #   Physical Maximum (315)
    0x65, 0x14,        #   Unit (English Rotation: degrees)
    0x75, 0x04,        #   Report Size (4)
    0x95, 0x01,        #   Report Count (1)
    0x81, 0x42,        #   Input (Data, Variable, Absolute, Null State)
    0x65, 0x00,        #   Unit (None)
    0xA4,              #   Push
    0x06, 0x00, 0xFF,  #     Usage Page (Vendor Defined 0xFF00)
    0x09, 0x20,        #     Usage (0x20)
    0x75, 0x08,        #     Report Size (8)
    0x95, 0x01,        #     Report Count (1)
    0x81, 0x03,        #     Input (Constant, Variable): a pad byte
    0x09, 0x21,        #     Usage (0x21)
    0x95, 0x02,        #     Report Count (2)
    0x91, 0x02,        #     Output (Data, Variable): rumble motors, not an input
    0xB4,              #   Pop (Generic Desktop, 4-bit size, count 1, 0..7 again)
    0x85, 0x02,        #   Report ID (2)
    0x09, 0x36,        #   Usage (Slider)
    0x09, 0x37,        #   Usage (Dial)
    0x15, 0x00,        #   Logical Minimum (0)
    0x26, 0xFF, 0x03,  #   Logical Maximum (1023)
    0x75, 0x0A,        #   Report Size (10)
    0x95, 0x02,        #   Report Count (2)
    0x81, 0x02,        #   Input (Data, Variable, Absolute)
    0x75, 0x04,        #   Report Size (4)
    0x95, 0x01,        #   Report Count (1)
    0x81, 0x03,        #   Input (Constant): 4 bits of padding
    0xC0,              # End Collection
])

GAMEPAD_VID, GAMEPAD_PID = 0x046D, 0xC21D
HAT_NULL = 8  # any hat value outside 0..7 means "centred"


def gamepad_report(x: int = 0, y: int = 0, rx: int = 0, ry: int = 0, z: int = 0, rz: int = 0,
                   buttons: int = 0, hat: int = HAT_NULL) -> bytes:
    """Report 1 of the game pad: sticks -32768..32767, triggers 0..255, a 12-bit button mask
    (bit 0 = button 1), hat 0..7 (0 = north, clockwise) or 8 for centred. 14 bytes with its ID."""
    return (bytes([1]) + b"".join(int(v).to_bytes(2, "little", signed=True) for v in (x, y, rx, ry))
            + bytes([z & 0xFF, rz & 0xFF])
            + ((buttons & 0xFFF) | (hat & 0xF) << 12).to_bytes(2, "little") + b"\x00")


def knobs_report(slider: int = 0, dial: int = 0) -> bytes:
    """Report 2 of the game pad: two 10-bit knobs (0..1023). 4 bytes with its ID."""
    return bytes([2]) + ((slider & 0x3FF) | (dial & 0x3FF) << 10).to_bytes(3, "little")


def gamepad_motion(period: int = 200) -> Iterator[bytes]:
    """An endless, repeating performance on the game pad: sticks circling, triggers pulsing,
    buttons counting, the hat turning, and a knobs report every tenth report."""
    for i in itertools.count():
        phase = 2 * math.pi * (i % period) / period
        if i % 10 == 9:
            yield knobs_report(int(511.5 + 511.5 * math.sin(phase)), int(511.5 - 511.5 * math.sin(phase)))
            continue
        yield gamepad_report(
            x=round(32767 * math.cos(phase)), y=round(32767 * math.sin(phase)),
            rx=round(-32767 * math.sin(phase)), ry=round(16000 * math.cos(2 * phase)),
            z=round(127.5 + 127.5 * math.sin(phase)), rz=round(127.5 - 127.5 * math.sin(phase)),
            buttons=(i // 25) & 0xFFF, hat=(i // 25) % 9)


class FakeHidHardware:
    """One fake HID device on the fake bus: what it says about itself and what it sends."""

    def __init__(self, vendor_id: int, product_id: int, descriptor: bytes | Sequence[int] | None,
                 reports: Iterable[bytes] | None = None, rate: float | None = None,
                 serial: str = "FAKE0001", path: bytes | None = None, manufacturer: str = "facepuppet",
                 product: str = "Fake HID device", usage_page: int = 0x01, usage: int = 0x05,
                 interface_number: int = 0) -> None:
        self.vendor_id, self.product_id, self.serial = vendor_id, product_id, serial
        self.path = path or f"fake-hid:{vendor_id:04x}:{product_id:04x}:{serial}".encode()
        self.descriptor = None if descriptor is None else bytes(descriptor)
        self.manufacturer, self.product = manufacturer, product
        self.usage_page, self.usage, self.interface_number = usage_page, usage, interface_number
        self.rate = rate
        self._script = iter(reports) if reports is not None else None
        self._pending: deque[bytes] = deque()
        self._cond = threading.Condition()
        self._plugged = True
        self.generation = 0  # bumped by every unplug: handles opened before it are stale
        self._next_due = 0.0
        self.reads = 0  # reports handed out

    # -- the test's side ---------------------------------------------------------------------

    def feed(self, *reports: bytes | Sequence[int]) -> None:
        """Queue input reports (played before the script's next ones)."""
        with self._cond:
            self._pending.extend(bytes(r) for r in reports)
            self._cond.notify_all()

    def unplug(self) -> None:
        """Pull the plug: reads raise OSError, opens fail, queued reports are lost."""
        with self._cond:
            self._plugged = False
            self.generation += 1
            self._pending.clear()
            self._cond.notify_all()

    def replug(self) -> None:
        """Plug it back in: it can be opened again (old handles stay stale)."""
        with self._cond:
            self._plugged = True
            self._cond.notify_all()

    @property
    def plugged(self) -> bool:
        return self._plugged

    def info(self) -> dict[str, Any]:
        """Its entry in ``enumerate()``, with hidapi's keys."""
        return {"path": self.path, "vendor_id": self.vendor_id, "product_id": self.product_id,
                "serial_number": self.serial, "release_number": 0x0100,
                "manufacturer_string": self.manufacturer, "product_string": self.product,
                "usage_page": self.usage_page, "usage": self.usage,
                "interface_number": self.interface_number}

    # -- the handle's side -------------------------------------------------------------------

    def _take(self, generation: int, timeout: float | None) -> bytes | None:
        """The next report, waiting up to ``timeout`` seconds (None: forever) for one."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while True:
                if not self._plugged or generation != self.generation:
                    raise OSError("read error")
                if self._pending:
                    self.reads += 1
                    return self._pending.popleft()
                if self._script is not None:
                    now = time.monotonic()
                    if self.rate is None or now >= self._next_due:
                        report = next(self._script, None)
                        if report is None:
                            self._script = None
                            continue
                        if self.rate is not None:
                            self._next_due = max(self._next_due, now) + 1.0 / self.rate
                        self.reads += 1
                        return bytes(report)
                    wake = self._next_due - now
                else:
                    wake = None
                if deadline is not None:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        return None
                    wake = left if wake is None else min(wake, left)
                self._cond.wait(wake)


class FakeHidDevice:
    """What ``FakeHidModule.device()`` returns: a handle with ``hid.device``'s methods."""

    def __init__(self, module: FakeHidModule) -> None:
        self._module = module
        self._hw: FakeHidHardware | None = None
        self._generation = 0
        self._blocking = True

    def _open(self, hw: FakeHidHardware | None) -> None:
        if hw is None or not hw.plugged:
            raise OSError("open failed")
        self._hw, self._generation, self._blocking = hw, hw.generation, True
        self._module.opened.append(self)

    def open(self, vendor_id: int = 0, product_id: int = 0, serial_number: str | None = None) -> None:
        self._open(next((hw for hw in self._module.hardware if hw.plugged
                         and hw.vendor_id == vendor_id and hw.product_id == product_id
                         and (serial_number is None or hw.serial == serial_number)), None))

    def open_path(self, path: bytes) -> None:
        if not isinstance(path, bytes):
            raise TypeError("open_path() argument 'path' must be bytes")
        self._open(next((hw for hw in self._module.hardware if hw.plugged and hw.path == path), None))

    def _handle(self) -> FakeHidHardware:
        if self._hw is None:
            raise ValueError("not open")
        return self._hw

    def close(self) -> None:
        self._hw = None

    def set_nonblocking(self, v: int) -> int:
        self._handle()
        self._blocking = not v
        return 0

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        hw = self._handle()
        if timeout_ms > 0:
            timeout: float | None = timeout_ms / 1000.0
        else:
            timeout = None if self._blocking else 0.0
        report = hw._take(self._generation, timeout)
        return [] if report is None else list(report[:max_length])

    def get_report_descriptor(self, max_length: int = 4096) -> list[int]:
        hw = self._handle()
        if not hw.plugged or self._generation != hw.generation:
            raise OSError("get report descriptor error")
        if hw.descriptor is None:
            raise OSError("get report descriptor error")
        return list(hw.descriptor[:max_length])

    def get_manufacturer_string(self) -> str:
        return self._handle().manufacturer

    def get_product_string(self) -> str:
        return self._handle().product

    def get_serial_number_string(self) -> str:
        return self._handle().serial

    def write(self, buff: Any) -> int:
        self._handle()
        return len(bytes(buff))

    def error(self) -> str:
        self._handle()
        return ""


class FakeHidModule:
    """Stands in for the ``hid`` module: ``device()`` and ``enumerate()`` over fake hardware."""

    def __init__(self, *hardware: FakeHidHardware) -> None:
        self.hardware = list(hardware)
        self.opened: list[FakeHidDevice] = []  # every handle ever opened (tests look at them)

    def device(self) -> FakeHidDevice:
        return FakeHidDevice(self)

    def enumerate(self, vendor_id: int = 0, product_id: int = 0) -> list[dict[str, Any]]:
        return [hw.info() for hw in self.hardware if hw.plugged
                and (not vendor_id or hw.vendor_id == vendor_id)
                and (not product_id or hw.product_id == product_id)]

    def unplug(self) -> None:
        for hw in self.hardware:
            hw.unplug()

    def replug(self) -> None:
        for hw in self.hardware:
            hw.replug()


def gamepad(reports: Iterable[bytes] | None = None, rate: float | None = None,
            serial: str = "FAKE0001") -> FakeHidHardware:
    """A fake USB game pad (046d:c21d, ``GAMEPAD_DESCRIPTOR``); by default it plays nothing until
    fed (``reports=gamepad_motion()`` for an endless performance)."""
    return FakeHidHardware(GAMEPAD_VID, GAMEPAD_PID, GAMEPAD_DESCRIPTOR, reports, rate, serial=serial,
                           product="Fake Game Pad")
