"""What is plugged in: the controllers a puppeteer could open, as device URLs, in well under a second.

Each backend that can look (its module's ``discover()``) asks its own library or the system:
pyserial's port list (with the USB vendor:product ids), hidapi's enumeration, mido's port names,
and the Linux network interfaces for CAN (SocketCAN interfaces that are up). python-can's
``detect_available_configs`` is not asked: it loads every vendor driver it knows (seconds) and
names configurations that could exist (``virtual``, ``udp_multicast``), not controllers that are
connected; other CAN adapters are opened by URL. A kind whose library is missing, or whose system
is absent (no ALSA sequencer for MIDI, no SocketCAN), is reported as such rather than failing the
rest.
"""

from __future__ import annotations

import importlib

from devices import backends
from devices.base import DeviceError, Found


def discover() -> dict[str, list[Found] | str]:
    """Per backend that can look, the devices found, or a line saying why none could be listed."""
    out: dict[str, list[Found] | str] = {}
    for kind, module_name in backends().items():
        try:
            find = getattr(importlib.import_module(module_name), "discover", None)
            if find is not None:
                out[kind] = find()
        except ImportError as exc:
            out[kind] = f"library {exc.name!r} not installed"
        except (OSError, DeviceError) as exc:
            out[kind] = str(exc)
    return out


def report(found: dict[str, list[Found] | str]) -> str:
    """The discovery result as the text ``puppet devices`` prints."""
    lines = []
    for kind, items in found.items():
        if isinstance(items, str):
            lines.append(f"{kind}: {items}")
        elif not items:
            lines.append(f"{kind}: none found")
        else:
            lines.append(f"{kind}:")
            lines += [f"  {item.url}  {item.description}" for item in items]
    return "\n".join(lines)
