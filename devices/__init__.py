"""Input devices: hardware adapters and simulated devices that yield Samples.

A device is named by a URL, in the spirit of pyserial's ``serial_for_url`` and python-can's
interfaces chosen by name: ``open_device("serial:///dev/ttyACM0?baudrate=115200")``. The scheme
picks the backend, one module each, imported only when used (so a missing optional library only
matters to the devices that need it); the rest of the URL is the backend's business.

A backend module exposes:

* ``DEVICE``: its ``Device`` class, built by ``DEVICE.from_url(url, name)``;
* ``TWIN`` (optional): its ``devices.twin.Twin``, the device's wire simulated, so a take can be
  replayed through the real adapter (``open_twin``);
* ``discover()`` (optional): the devices of its kind plugged in now, as ``Found`` URLs
  (``devices.discovery``).

``BACKENDS`` names the built-in ones. A third party adds a backend without touching this package,
as ``can.interface`` does for python-can: an entry point in the group ``facepuppet.devices`` whose
name is the URL scheme and whose value is the module (``[project.entry-points."facepuppet.devices"]
mydevice = "mypackage.mydevice"``). A built-in scheme cannot be taken over.
"""

from __future__ import annotations

import functools
import importlib
import importlib.metadata
import warnings
from collections.abc import Mapping
from types import ModuleType
from typing import TYPE_CHECKING, Any

from devices.base import Counters, Device, DeviceError, DeviceLost, Found, Sample, Sound, State, Url

if TYPE_CHECKING:
    from devices.twin import Twin

BACKENDS: dict[str, str] = {
    "serial": "devices.serial_port",
    "hid": "devices.hid_device",
    "midi": "devices.midi_device",
    "can": "devices.can_device",
    "osc": "devices.osc_device",
    "sim": "devices.sim_device",
    "replay": "devices.replay_device",
    "audio": "devices.audio_device",
    "wav": "devices.wav_device",
    "api": "devices.api_device",
    "keys": "devices.keys_device",
}
"""URL scheme -> module of its built-in backend."""

ENTRY_POINTS = "facepuppet.devices"


@functools.cache
def backends() -> dict[str, str]:
    """Every backend, URL scheme -> module: the built-in ones and those installed packages add."""
    found = dict(BACKENDS)
    for entry in importlib.metadata.entry_points(group=ENTRY_POINTS):
        if entry.name in BACKENDS:
            warnings.warn(f"entry point {entry.name} = {entry.value} ({ENTRY_POINTS}) would take over a "
                          "built-in device scheme: ignored", stacklevel=2)
        else:
            found[entry.name] = entry.value
    return found


def backend(scheme: str, what: str) -> ModuleType:
    """The backend module of a URL scheme, imported now; ``what`` names the URL in errors."""
    known = backends()
    if scheme not in known:
        raise DeviceError(f"{what}: unknown scheme {scheme!r}; known: {sorted(known)}")
    try:
        return importlib.import_module(known[scheme])
    except ImportError as exc:
        raise DeviceError(f"{what}: the {scheme} backend needs {exc.name!r} (pip install {exc.name})") from None


def device_class(scheme: str, what: str) -> type[Device]:
    """The ``Device`` class of a URL scheme."""
    device: type[Device] = backend(scheme, what).DEVICE
    return device


def open_device(url: str, name: str | None = None) -> Device:
    """The device a URL names (not started yet: call ``start()`` or use it as a context manager)."""
    parsed = Url.parse(url)
    device = device_class(parsed.scheme, f"device URL {url!r}").from_url(parsed, name or url)
    device.url = url
    return device


def open_twin(url: str, name: str, wire_info: Mapping[str, Any] | None = None) -> Twin | None:
    """The twin of a logged device (its URL, name and ``wire_info``), its adapter open and ready:
    a ``devices.twin.Twin``. A URL whose backend has no wire (``replay://``) has none."""
    try:
        scheme = Url.parse(url).scheme
    except DeviceError:
        scheme = None
    twin = getattr(backend(scheme, f"{name}: {url!r}"), "TWIN", None) if scheme in backends() else None
    if twin is None:
        wired = ", ".join(f"{s}://" for s in twin_schemes())
        raise DeviceError(f"{name}: {url!r} cannot be replayed through a device: only device URLs with a wire "
                          f"have a twin ({wired})")
    try:
        opened: Twin = twin.from_url(url, name, wire_info or {})
        return opened
    except DeviceError as exc:
        if str(exc).startswith(f"{name}: "):
            raise
        raise DeviceError(f"{name}: no twin for {url!r}: {exc}") from None


def twin_schemes() -> list[str]:
    """The schemes whose backend has a twin (importing each backend whose library is here)."""
    out = []
    for scheme in backends():
        try:
            module = importlib.import_module(backends()[scheme])
        except ImportError:
            continue
        if getattr(module, "TWIN", None) is not None:
            out.append(scheme)
    return sorted(out)


__all__ = ["BACKENDS", "Counters", "Device", "DeviceError", "DeviceLost", "Found", "Sample", "Sound", "State", "Url",
           "backend", "backends", "device_class", "open_device", "open_twin", "twin_schemes"]
