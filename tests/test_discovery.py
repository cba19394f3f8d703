"""`puppet devices` lists what each library finds, and says why where it cannot."""

import subprocess
import sys
import types
from pathlib import Path

import pytest

from devices import backends, can_device, discovery, serial_port
from devices.base import Found
from devices.discovery import discover, report
from puppet import cli


def test_each_backend_that_can_look_reports_devices_or_why_not(monkeypatch):
    def missing():
        raise ImportError("no module", name="hid")

    def no_system():
        raise OSError("no MIDI system (ALSA)")

    finders = {"serial": lambda: [Found("serial", "serial:///dev/ttyACM0", "Arduino Uno")],
               "hid": missing, "midi": no_system, "can": list, "osc": None}
    for kind, find in finders.items():
        module = types.ModuleType(f"fake_{kind}_backend")
        if find is not None:
            module.discover = find
        monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setattr(discovery, "backends", lambda: {kind: f"fake_{kind}_backend" for kind in finders})
    text = report(discover())
    assert text.splitlines() == [
        "serial:", "  serial:///dev/ttyACM0  Arduino Uno",
        "hid: library 'hid' not installed", "midi: no MIDI system (ALSA)", "can: none found",
    ]


def test_puppet_devices_runs_on_this_machine(capsys):
    assert cli.main(["devices"]) == 0
    out = capsys.readouterr().out
    assert all(line.split(":")[0] in backends() or line.startswith("  ") for line in out.splitlines())


def test_puppet_devices_loads_no_face_renderer_or_scipy():
    """What keeps ``puppet devices`` under a second: the command imports the device libraries and
    nothing of the face side (scipy alone is about half a second to import)."""
    probe = ("import sys; from puppet import cli; cli.main(['devices']); "
             "print(sorted(m for m in sys.modules if m.split('.')[0] in ('scipy', 'moderngl', 'trimesh') "
             "or m in ('puppet.face.model', 'puppet.runtime.runtime', 'puppet.view.renderer', 'puppet.live.mappingfile')))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                          cwd=Path(__file__).resolve().parents[1])
    assert done.stdout.splitlines()[-1] == "[]"


def _interface(net, name: str, kind: str, flags: str, bitrate: str | None = None) -> None:
    folder = net / name
    folder.mkdir(parents=True)
    (folder / "type").write_text(kind + "\n")
    (folder / "flags").write_text(flags + "\n")
    if bitrate:
        (folder / "can_bittiming").mkdir()
        (folder / "can_bittiming" / "bitrate").write_text(bitrate + "\n")


def test_can_lists_the_socketcan_interfaces_that_are_up_and_nothing_else(tmp_path):
    _interface(tmp_path, "can0", "280", "0x40c1", "500000")
    _interface(tmp_path, "can1", "280", "0x80")  # down
    _interface(tmp_path, "eth0", "1", "0x1003")
    assert can_device.discover(tmp_path) == [Found("can", "can://socketcan/can0", "SocketCAN, up, 500,000 bit/s")]


def test_without_socketcan_the_reason_is_given(tmp_path):
    with pytest.raises(OSError, match="open a CAN adapter by URL"):
        can_device.discover(tmp_path / "absent")


def test_a_usb_serial_port_is_named_by_its_maker_and_usb_ids():
    from serial.tools.list_ports_common import ListPortInfo

    port = ListPortInfo("/dev/ttyACM0", skip_link_detection=True)
    port.vid, port.pid, port.manufacturer, port.product = 0x2341, 0x0043, "Arduino (www.arduino.cc)", "Uno"
    assert serial_port._serial_description(port) == "Arduino (www.arduino.cc) Uno USB 2341:0043"


def test_without_an_alsa_sequencer_midi_says_what_to_load():
    midi_device = pytest.importorskip("devices.midi_device")
    if not sys.platform.startswith("linux") or Path(midi_device.ALSA_SEQUENCER).exists():
        pytest.skip("this machine has an ALSA sequencer")
    line = next(line for line in report(discover()).splitlines() if line.startswith("midi:"))
    assert line.startswith("midi: no MIDI system") and "sudo modprobe snd-seq" in line
