"""HID input devices (game pads, joysticks, knob boxes) read through hidapi.

URLs (scheme ``hid``):

- ``hid://046d:c21d``: the first device with that vendor:product id (hex);
- ``hid://046d:c21d:SERIAL``: the one with that serial number;
- ``hid://path/<url-encoded path>``: the device at a platform path from ``hid.enumerate()``
  (``hid://path/%2Fdev%2Fhidraw3``, ``hid://path/1-2%3A1.0``);

with options:

- ``interface=N``, ``usage_page=0x01``, ``usage=0x05``: pick one interface of a composite device
  (looked up with ``hid.enumerate``, then opened by path);
- ``fields=name:bit_offset:bit_size[:min:max[:kind]];...`` and ``report_id=N``: the channels by
  hand (see ``FieldSpec``), for devices whose report descriptor cannot be read or is wrong;
  without them the channels come from the device's own report descriptor, named by usage
  (``X``, ``Y``, ``Z``, ``Rx``, ``Ry``, ``Rz``, ``Slider``, ``Dial``, ``Wheel``, ``hat``,
  ``button1``...; see ``devices.hid_descriptor``);
- ``raw=1``: logical values as read, not scaled to -1..1 / 0..1;
- ``length=N``: the read buffer (default: the longest report, at least 64 bytes);
- ``timeout_ms=N``: how long one read waits (default 20 ms; it never blocks longer).

Every read waits at most ``timeout_ms`` (``hid.device.read(n, timeout_ms)``), then the reports the
device has already queued are drained without waiting (``set_nonblocking(1)``), up to ``BATCH`` a
call. A report that is shorter than its fields, or carries a report ID the descriptor does not
declare, is counted in ``counters.bad_frames`` and skipped. hidapi raises ``OSError`` when a read
fails (the device was unplugged): the base class then reports LOST and reopens with backoff. A
device that opens but whose descriptor cannot be read (and no ``fields`` given) also fails its open
with an ``OSError`` that says so in ``counters.last_error``, so a live session never stops on it.
"""

from __future__ import annotations

import errno
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from typing import Any
from urllib.parse import quote, unquote

from devices.base import Device, DeviceError, DeviceLost, Found, Url
from devices.hid_descriptor import DescriptorError, FieldSpec, ReportLayout
from devices.simulated_hid import FakeHidHardware, FakeHidModule
from devices.twin import Twin

try:
    import hid
except ImportError:  # the backend says what to install when it is used
    hid = None

def _int(text: str, what: str, url: str) -> int:
    try:
        return int(text, 0) if text.lower().startswith("0x") else int(text)
    except ValueError:
        raise DeviceError(f"device URL {url!r}: {what} {text!r} is not an integer") from None


class HidDevice(Device):
    """A HID device read through a ``hid`` module (cython-hidapi, or ``FakeHidModule`` in tests)."""

    BATCH = 32  # most reports taken in one _read
    OPTIONS = frozenset({"interface", "usage_page", "usage", "fields", "report_id", "raw", "length", "timeout_ms"})

    def __init__(self, name: str, vendor_id: int | None = None, product_id: int | None = None,
                 serial: str | None = None, path: bytes | None = None, *,
                 fields: Sequence[FieldSpec | Mapping[str, Any]] | None = None, raw: bool = False,
                 interface: int | None = None, usage_page: int | None = None, usage: int | None = None,
                 length: int | None = None, timeout_ms: int = 20, hid_module: Any = None) -> None:
        super().__init__(name)
        if hid_module is None:
            if hid is None:
                raise DeviceError(f"{name}: HID devices need hidapi (pip install hidapi)")
            hid_module = hid
        if path is None and (vendor_id is None or product_id is None):
            raise DeviceError(f"{name}: a HID device needs vendor and product ids, or a path")
        if not 1 <= timeout_ms <= 1000:
            raise DeviceError(f"{name}: timeout_ms {timeout_ms} (expected 1..1000)")
        self.vendor_id, self.product_id, self.serial, self.path = vendor_id, product_id, serial, path
        self.interface, self.usage_page, self.usage = interface, usage_page, usage
        self.fields = None if fields is None else [f if isinstance(f, FieldSpec) else FieldSpec(**f)
                                                   for f in fields]
        self.raw, self.length, self.timeout_ms = raw, length, timeout_ms
        self._hid = hid_module
        self._dev: Any = None
        self._drain = False
        self.layout: ReportLayout | None = None
        if self.fields is not None:
            self.layout = ReportLayout([f.channel() for f in self.fields], raw)
        self.info: dict[str, str] = {}
        self.descriptor: bytes | None = None  # the report descriptor read at the last open

    @classmethod
    def from_url(cls, url: Url, name: str, *, fields: Sequence[FieldSpec | Mapping[str, Any]] | None = None,
                 hid_module: Any = None) -> HidDevice:
        text = f"{url.scheme}://{url.target}"
        cls.check_options(url)
        kw: dict[str, Any] = {}
        if url.target.startswith("path/"):
            path = unquote(url.target[len("path/"):])
            if not path:
                raise DeviceError(f"device URL {text!r}: expected hid://path/<url-encoded path>")
            kw["path"] = path.encode()
        else:
            parts = url.target.split(":", 2)
            if len(parts) < 2 or not all(parts[:2]):
                raise DeviceError(f"device URL {text!r}: expected hid://VID:PID[:SERIAL] (hex ids, "
                                  "e.g. hid://046d:c21d) or hid://path/<url-encoded path>")
            try:
                kw["vendor_id"], kw["product_id"] = int(parts[0], 16), int(parts[1], 16)
            except ValueError:
                raise DeviceError(f"device URL {text!r}: vendor and product ids are hex, e.g. 046d:c21d") from None
            if len(parts) == 3 and parts[2]:
                kw["serial"] = unquote(parts[2])
        o = url.options
        for key in ("interface", "usage_page", "usage", "length", "timeout_ms"):
            if key in o:
                kw[key] = _int(o[key], key, text)
        kw["raw"] = o.get("raw", "0").lower() in ("1", "true", "yes", "on")
        if "fields" in o:
            report_id = _int(o.get("report_id", "0"), "report_id", text)
            try:
                fields = [FieldSpec.parse(f, report_id) for f in o["fields"].split(";") if f.strip()]
            except ValueError as exc:
                raise DeviceError(f"device URL {text!r}: {exc}") from None
        elif "report_id" in o:
            raise DeviceError(f"device URL {text!r}: report_id only goes with fields=")
        return cls(name, fields=fields, hid_module=hid_module, **kw)

    # -- Device ------------------------------------------------------------------------------

    def _find_path(self) -> bytes:
        """The path of the interface the options pick, through ``enumerate``."""
        for info in self._hid.enumerate(self.vendor_id, self.product_id):
            if ((self.serial is None or info.get("serial_number") == self.serial)
                    and (self.interface is None or info.get("interface_number") == self.interface)
                    and (self.usage_page is None or info.get("usage_page") == self.usage_page)
                    and (self.usage is None or info.get("usage") == self.usage)):
                path: bytes = info["path"]
                return path
        raise OSError(f"no HID device {self.vendor_id:04x}:{self.product_id:04x} with "
                      f"interface={self.interface} usage_page={self.usage_page} usage={self.usage}")

    def _open_by_ids(self, dev: Any) -> None:
        """``dev.open`` by vendor and product id; hidapi's bare "open failed" told apart as a
        device that is not plugged in or one that is there but will not open (permission)."""
        try:
            dev.open(self.vendor_id, self.product_id, self.serial)
        except OSError as exc:
            ids = f"{self.vendor_id:04x}:{self.product_id:04x}"
            if not any(self.serial is None or info.get("serial_number") == self.serial
                       for info in self._hid.enumerate(self.vendor_id, self.product_id)):
                raise OSError(errno.ENODEV, f"no HID device {ids} plugged in") from None
            raise OSError(errno.EACCES, f"HID device {ids} is plugged in but would not open ({exc}): on Linux, "
                                        "no permission on /dev/hidraw* (a udev rule: see the HID page)") from None

    def _open(self) -> None:
        dev = self._hid.device()
        if self.path is not None:
            dev.open_path(self.path)
        elif self.interface is not None or self.usage_page is not None or self.usage is not None:
            dev.open_path(self._find_path())
        else:
            self._open_by_ids(dev)
        try:
            try:
                self._drain = dev.set_nonblocking(1) == 0
            except (OSError, ValueError, AttributeError):
                self._drain = False
            if self.fields is None:
                self.layout = self._layout_from_descriptor(dev)
            self.info = {}
            for key, getter in (("manufacturer", "get_manufacturer_string"), ("product", "get_product_string")):
                try:
                    self.info[key] = getattr(dev, getter)() or ""
                except (OSError, ValueError, AttributeError):
                    pass
        except BaseException:
            dev.close()
            raise
        assert self.layout is not None
        self._length = max(self.length or 0, self.layout.report_length, 64)
        self._dev = dev

    def _layout_from_descriptor(self, dev: Any) -> ReportLayout:
        try:
            try:
                descriptor = dev.get_report_descriptor()
            except TypeError:  # bindings that want a buffer size
                descriptor = dev.get_report_descriptor(4096)
        except (OSError, ValueError, AttributeError) as exc:
            raise OSError(f"{self.name}: cannot read the HID report descriptor ({exc or type(exc).__name__}); "
                          "name the channels with ?fields=name:bit_offset:bit_size;...") from None
        self.descriptor = bytes(descriptor)
        try:
            layout = ReportLayout.from_descriptor(descriptor, self.raw)
        except DescriptorError as exc:
            raise OSError(f"{self.name}: {exc}; name the channels with ?fields=...") from None
        if not layout.channels:
            raise OSError(f"{self.name}: the HID report descriptor declares no input values")
        return layout

    def wire_info(self) -> dict[str, Any]:
        """What names and places the channels, so a take can rebuild the same reports later: the
        fields given by hand (they may come from a mapping, not the URL), else the report
        descriptor read from the hardware (hex); ``{}`` before the descriptor was first read."""
        if self.fields is not None:
            return {"fields": [{k: v for k, v in asdict(f).items() if k != "extra"} for f in self.fields]}
        if self.descriptor is None:
            return {}
        return {"report_descriptor": self.descriptor.hex()}

    def _read(self) -> list[dict[str, float]]:
        dev = self._dev
        try:
            data = dev.read(self._length, self.timeout_ms)
        except ValueError as exc:  # the handle was closed under us
            raise DeviceLost(f"{self.name}: {exc}") from None
        if not data:
            return []
        decode = self.layout.decode  # type: ignore[union-attr]
        out = []
        taken = 1
        while True:
            values = decode(bytes(data))
            if values is None:
                self.counters.bad_frames += 1
            else:
                out.append(values)
            if not self._drain or taken >= self.BATCH:
                return out
            data = dev.read(self._length)  # non-blocking: what is queued already, or []
            if not data:
                return out
            taken += 1

    def _close(self) -> None:
        dev, self._dev = self._dev, None
        if dev is not None:
            try:
                dev.close()
            except Exception:
                pass


def discover(hid_module: Any = None) -> list[Found]:
    """Every HID device plugged in now, by path so each interface of a composite device shows."""
    module = hid_module or hid
    if module is None:
        raise DeviceError("HID devices need hidapi (pip install hidapi)")
    out = []
    for info in module.enumerate():
        path = info["path"].decode(errors="replace") if isinstance(info["path"], bytes) else str(info["path"])
        desc = (f"{info['vendor_id']:04x}:{info['product_id']:04x} {info.get('manufacturer_string') or ''} "
                f"{info.get('product_string') or ''} (interface {info.get('interface_number')}, usage page "
                f"0x{info.get('usage_page', 0):02x} usage 0x{info.get('usage', 0):02x})").replace("  ", " ")
        out.append(Found("hid", f"hid://path/{quote(path, safe='')}", desc))
    return out


class HidTwin(Twin):
    """``hid://`` wires: one ``FakeHidHardware`` answering to the logged URL (ids, serial, path,
    interface, usage) with the logged report descriptor, read by a ``HidDevice`` opened from that
    URL; a logged reading goes back as the report ``ReportLayout.encode`` packs.

    The channels come from ``wire_info``: the hand-given ``fields``, or the ``report_descriptor``
    (hex) the device read. Values go through the field's integer range, so only values the
    adapter's scaling produces come back exactly (buttons 0/1, hats in steps or -1, axes at
    raw / max, ...).
    """
    device: HidDevice  # the adapter this twin feeds

    def __init__(self, device: HidDevice, hardware: FakeHidHardware, url: str) -> None:
        self.hardware = hardware
        super().__init__(device, url)

    @classmethod
    def from_url(cls, url: str, name: str, wire_info: Mapping[str, Any]) -> HidTwin:
        descriptor = wire_info.get("report_descriptor")
        fields = wire_info.get("fields")
        if descriptor is None and fields is None and "fields" not in Url.parse(url).options:
            raise DeviceError(f"{name}: the take keeps no HID report descriptor or fields for {url!r} "
                              "(wire_info), so its reports cannot be rebuilt")
        module = FakeHidModule()
        device = HidDevice.from_url(Url.parse(url), name, fields=fields, hid_module=module)
        module.hardware.append(FakeHidHardware(
            device.vendor_id or 0, device.product_id or 0,
            None if descriptor is None else bytes.fromhex(descriptor), serial=device.serial or "TWIN",
            path=device.path, usage_page=device.usage_page or 0, usage=device.usage or 0,
            interface_number=device.interface or 0))
        return cls(device, module.hardware[0], url)

    def _put(self, values: Mapping[str, float]) -> int:
        self.hardware.feed(self.device.layout.encode(values))  # type: ignore[union-attr]  # open: laid out
        return 1


DEVICE, TWIN = HidDevice, HidTwin
