"""What is connected: the controllers a puppeteer could open, as device URLs.

Each kind is asked through its own library (pyserial's port list, hidapi's enumeration, mido's
port names, python-can's detected configurations). A kind whose library is missing, or whose
system is absent (no ALSA sequencer for MIDI), is reported as such rather than failing the rest.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from urllib.parse import quote
from dataclasses import dataclass


@dataclass(frozen=True)
class Found:
    """One connectable device: its URL and what the system says about it."""

    kind: str
    url: str
    description: str


def serial_ports() -> list[Found]:
    from serial.tools import list_ports

    return [Found("serial", f"serial://{p.device}", " ".join(filter(None, (p.description, p.hwid))))
            for p in sorted(list_ports.comports(), key=lambda p: p.device)]


def hid_devices() -> list[Found]:
    import hid  # noqa: F401 -- a missing hidapi is reported as such

    from .hid_device import available

    return [Found("hid", url, description) for url, description in available()]


def midi_ports() -> list[Found]:
    import mido

    try:
        names = mido.get_input_names()
    except Exception as exc:  # rtmidi's own SystemError when the machine has no MIDI system
        raise OSError(f"no MIDI system ({str(exc).splitlines()[0]})") from None
    return [Found("midi", f"midi://{quote(name, safe=' ')}", "MIDI input") for name in names]


def can_configs() -> list[Found]:
    import can

    quiet = logging.getLogger("can")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)  # every absent vendor driver would log a line otherwise
    try:
        configs = can.detect_available_configs()
    finally:
        quiet.setLevel(level)
    return [Found("can", f"can://{c['interface']}/{c.get('channel', '')}", "python-can detected")
            for c in configs]


KINDS: dict[str, Callable[[], list[Found]]] = {
    "serial": serial_ports, "hid": hid_devices, "midi": midi_ports, "can": can_configs,
}


def discover() -> dict[str, list[Found] | str]:
    """Per kind, the devices found, or a line saying why none could be listed."""
    out: dict[str, list[Found] | str] = {}
    for kind, find in KINDS.items():
        try:
            out[kind] = find()
        except ImportError as exc:
            out[kind] = f"library {exc.name!r} not installed"
        except OSError as exc:
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
