"""What is plugged in: the controllers a puppeteer could open, as device URLs, in well under a second.

Each kind is asked through its own library or the system: pyserial's port list (with the USB
vendor:product ids), hidapi's enumeration, mido's port names, and the Linux network interfaces for
CAN (SocketCAN interfaces that are up: ``/sys/class/net/*``, type 280). python-can's
``detect_available_configs`` is not asked: it loads every vendor driver it knows (seconds) and
names configurations that could exist (``virtual``, ``udp_multicast``), not controllers that are
connected; other CAN adapters are opened by URL. A kind whose library is missing, or whose system
is absent (no ALSA sequencer for MIDI, no SocketCAN), is reported as such rather than failing the
rest.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote


@dataclass(frozen=True)
class Found:
    """One connectable device: its URL and what the system says about it."""

    kind: str
    url: str
    description: str


def serial_ports() -> list[Found]:
    from serial.tools import list_ports

    return [Found("serial", f"serial://{p.device}", _serial_description(p))
            for p in sorted(list_ports.comports(), key=lambda p: p.device)]


def _serial_description(port) -> str:
    usb = f"USB {port.vid:04x}:{port.pid:04x}" if port.vid is not None and port.pid is not None else None
    words = (port.manufacturer, port.product) if usb else (port.description,)
    return " ".join(dict.fromkeys(w for w in (*words, usb) if w and w != "n/a")) or "serial port"


def hid_devices() -> list[Found]:
    import hid  # noqa: F401 -- a missing hidapi is reported as such

    from devices.hid_device import available

    return [Found("hid", url, description) for url, description in available()]


ALSA_SEQUENCER = "/dev/snd/seq"
"""What MIDI needs on Linux: the ALSA sequencer's device (absent in many containers and VMs)."""


def midi_ports() -> list[Found]:
    import mido

    try:
        with _quiet_stderr():  # ALSA prints its own complaint straight to fd 2 when there is no sequencer
            names = mido.get_input_names()
    except Exception as exc:  # rtmidi's own SystemError when the machine has no MIDI system
        detail = str(exc).splitlines()[0]
        if sys.platform.startswith("linux") and not Path(ALSA_SEQUENCER).exists():
            detail = f"no {ALSA_SEQUENCER}: load the ALSA sequencer, sudo modprobe snd-seq"
        raise OSError(f"no MIDI system ({detail})") from None
    return [Found("midi", f"midi://{quote(name, safe=' ')}", "MIDI input") for name in names]


def can_interfaces(net: Path = Path("/sys/class/net")) -> list[Found]:
    """SocketCAN interfaces that are up (``net``: the kernel's network interface folder)."""
    if not net.is_dir():
        raise OSError("no SocketCAN here (Linux only); open a CAN adapter by URL, e.g. can://pcan/PCAN_USBBUS1")
    found = []
    for interface in sorted(net.iterdir()):
        if _read(interface / "type") != CAN_TYPE:
            continue
        flags = int(_read(interface / "flags") or "0", 16)
        if flags & IFF_UP:
            bitrate = _read(interface / "can_bittiming" / "bitrate")
            found.append(Found("can", f"can://socketcan/{interface.name}",
                               f"SocketCAN, up{f', {int(bitrate):,} bit/s' if bitrate else ''}"))
    return found


CAN_TYPE = "280"
"""ARPHRD_CAN: a network interface of this type is a CAN bus."""
IFF_UP = 0x1


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence what C libraries write to the process's stderr (file descriptor 2) meanwhile."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _read(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except OSError:
        return None


KINDS: dict[str, Callable[[], list[Found]]] = {
    "serial": serial_ports, "hid": hid_devices, "midi": midi_ports, "can": can_interfaces,
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
