"""Input devices: hardware adapters and simulated devices that yield Samples.

A device is named by a URL, in the spirit of pyserial's ``serial_for_url`` and python-can's
interfaces chosen by name: ``open_device("serial:///dev/ttyACM0?baudrate=115200")``. The scheme
picks the backend module (imported only when used, so a missing optional library only matters to
the devices that need it); the rest of the URL is the backend's business.
"""

from __future__ import annotations

from devices.base import Counters, Device, DeviceError, DeviceLost, Sample, State, Url, table_class

BACKENDS: dict[str, str] = {
    "can": "devices.can_device:CanDevice",
    "hid": "devices.hid_device:HidDevice",
    "midi": "devices.midi_device:MidiDevice",
    "osc": "devices.osc_device:OscDevice",
    "replay": "devices.replay_device:ReplayDevice",
    "serial": "devices.serial_port:SerialDevice",
    "sim": "devices.simulated_serial:SimulatedSerialDevice",
}
"""URL scheme -> "module:Class" of its backend (a new backend adds its line here)."""


def open_device(url: str, name: str | None = None) -> Device:
    """The device a URL names (not started yet: call ``start()`` or use it as a context manager)."""
    parsed = Url.parse(url)
    if parsed.scheme not in BACKENDS:
        raise DeviceError(f"device URL {url!r}: unknown scheme {parsed.scheme!r}; known: {sorted(BACKENDS)}")
    try:
        backend = table_class(BACKENDS[parsed.scheme])
    except ImportError as exc:
        raise DeviceError(f"device URL {url!r}: the {parsed.scheme} backend needs {exc.name!r} "
                          f"(pip install {exc.name})") from None
    device = backend.from_url(parsed, name or url)
    device.url = url
    return device


__all__ = ["BACKENDS", "Counters", "Device", "DeviceError", "DeviceLost", "Sample", "State", "Url", "open_device"]
