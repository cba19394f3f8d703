"""`puppet devices` lists what each library finds, and says why where it cannot."""

from devices import discovery
from devices.discovery import Found, discover, report
from puppet import cli


def test_each_kind_reports_devices_or_why_not(monkeypatch):
    def missing():
        raise ImportError("no module", name="hid")

    def no_system():
        raise OSError("no MIDI system (ALSA)")

    monkeypatch.setattr(discovery, "KINDS", {
        "serial": lambda: [Found("serial", "serial:///dev/ttyACM0", "Arduino Uno")],
        "hid": missing, "midi": no_system, "can": lambda: [],
    })
    text = report(discover())
    assert text.splitlines() == [
        "serial:", "  serial:///dev/ttyACM0  Arduino Uno",
        "hid: library 'hid' not installed", "midi: no MIDI system (ALSA)", "can: none found",
    ]


def test_puppet_devices_runs_on_this_machine(capsys):
    assert cli.main(["devices"]) == 0
    out = capsys.readouterr().out
    assert all(line.split(":")[0] in discovery.KINDS or line.startswith("  ") for line in out.splitlines())
