"""puppet.live.calibrate: rest + sweep recordings -> min / centre / max written back into the YAML."""

from __future__ import annotations

import io
import time

import pytest
import yaml

import puppet.live.calibrate as cal
from devices.base import Device
from puppet.cli import main
from puppet.io.shipped import shipped_mappings
from puppet.live.calibrate import CalibrationError, calibrate, write_calibration
from puppet.live.mappingfile import MappingError, load_mapping

MAPPING = """\
# A test box: the first comment line must survive calibration.
description: calibration test
devices:
  box:
    url: "sim://joystick?protocol=ascii"   # never opened in these tests
channels:
  box.ch0:                # jaw slider
    min: 0
    max: 1023
    dead_zone: 0.02
  box.ch1:                # brow, centre detent
    range: bipolar
    min: 0
    centre: 512
    max: 1023
  box.ch2:                # a slider nobody touches
    min: 0
    max: 1023
  box.ch3:
targets:
  - {fap: open_jaw, source: box.ch0, range: [0, 700]}
  - {fap: raise_l_i_eyebrow, source: box.ch1, range: [-200, 200]}
  - {fap: raise_r_i_eyebrow, source: box.ch2, range: [0, 200]}
  - {fap: raise_r_o_eyebrow, source: box.ch3, range: [-200, 200]}
"""


class PhasedBox(Device):
    """A slider box in memory: phase 0 (before Enter) junk, 1 rest, 2 sweep; ch3 never reports."""

    @classmethod
    def from_url(cls, url, name):
        return cls()

    def __init__(self) -> None:
        super().__init__("box")
        self.phase = 0
        self.k = 0

    def _open(self) -> None:
        pass

    def _read(self):
        time.sleep(0.002)
        out = []
        for _ in range(20):
            k = self.k = self.k + 1
            if self.phase == 0:            # before the first Enter: must be ignored
                out.append({"ch0": -500.0, "ch1": 5000.0, "ch2": 300.0})
            elif self.phase == 1:          # rest, with a little noise
                out.append({"ch0": 12.0 + k % 2, "ch1": 500.0 + k % 3, "ch2": 300.0 + k % 2})
            else:                          # sweep: 100 evenly used levels, one glitch
                ch0 = 99999.0 if k % 5000 == 0 else 10.0 + (k % 100) * 10
                out.append({"ch0": ch0, "ch1": 20.0 + (k % 99) * 10, "ch2": 300.0 + k % 2})
        return out

    def _close(self) -> None:
        pass


def run(path, box):
    prompts = []

    def prompt(text):
        prompts.append(text)
        time.sleep(0.05)          # samples of the previous phase pile up: they must be dropped
        box.phase += 1

    out = io.StringIO()
    result = calibrate(path, rest_seconds=0.3, sweep_seconds=0.4, devices={"box": box}, prompt=prompt, out=out)
    return result, out.getvalue(), prompts


@pytest.fixture
def mapping_file(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(MAPPING, encoding="utf-8")
    return path


def test_calibrate_measures_reports_and_rewrites_the_yaml(mapping_file):
    box = PhasedBox()
    try:
        result, out, prompts = run(mapping_file, box)
    finally:
        box.close()
    assert len(prompts) == 2

    assert result["box.ch0"]["min"] == 10 and result["box.ch0"]["max"] == 1000   # glitch ignored
    assert result["box.ch0"]["centre"] == 12  # whole counts in, whole counts out (the median 12.5, rounded)
    assert result["box.ch1"] == {"min": 20, "centre": 501, "max": 1000, "samples": result["box.ch1"]["samples"]}
    assert result["box.ch1"]["samples"] > 300
    assert result["box.ch3"] == {"min": None, "centre": None, "max": None, "samples": 0}

    assert "warning: box.ch2: never moved" in out
    assert "warning: box.ch3: never reported" in out
    assert "box.ch0" not in "".join(l for l in out.splitlines() if l.startswith("warning"))

    text = mapping_file.read_text(encoding="utf-8")
    assert "# A test box: the first comment line must survive calibration." in text
    assert "# jaw slider" in text and "# brow, centre detent" in text and "# never opened" in text
    assert "  box.ch0:                # jaw slider\n    min: 10\n    max: 1000\n    dead_zone: 0.02\n" in text
    assert "    range: bipolar\n    min: 20\n    centre: 501\n    max: 1000\n" in text
    assert "  box.ch2:                # a slider nobody touches\n    min: 0\n    max: 1023\n" in text  # untouched
    assert "  - {fap: open_jaw, source: box.ch0, range: [0, 700]}\n" in text  # sequence style kept

    spec = load_mapping(mapping_file)._channels
    assert (spec["box.ch0"].low, spec["box.ch0"].k) == (10, pytest.approx(1 / 990))
    assert (spec["box.ch1"].low, spec["box.ch1"].centre) == (20, 501)
    assert (mapping_file.parent / "m.yaml.bak").read_text(encoding="utf-8") == MAPPING


def test_missing_entries_and_keys_are_added_in_order(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(MAPPING.replace("  box.ch3:\n", "  box.ch3:\n    range: bipolar   # keep me\n"), encoding="utf-8")
    write_calibration(path, {"box.ch3": {"min": -5, "centre": 0.5, "max": 7.25},
                             "box.ch9": {"min": 1, "max": 2}})
    text = path.read_text(encoding="utf-8")
    assert "    range: bipolar   # keep me\n    min: -5\n    centre: 0.5\n    max: 7.25\n" in text
    assert "  box.ch9:\n    min: 1\n    max: 2\n" in text
    m = load_mapping(path)
    assert m._channels["box.ch9"].low == 1 and m._channels["box.ch3"].centre == 0.5


def test_a_result_that_does_not_load_restores_the_original(mapping_file):
    with pytest.raises(CalibrationError, match="does not load.*restored"):
        write_calibration(mapping_file, {"box.ch0": {"min": 900, "max": 100}})
    assert mapping_file.read_text(encoding="utf-8") == MAPPING
    assert not [p for p in mapping_file.parent.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("content", [None, "devices: {}\nchannels: {box.ch0: {}}\ntargets: []\n"])
def test_bad_mapping_fails_before_any_device_opens(tmp_path, monkeypatch, content):
    opened = []
    monkeypatch.setattr(cal, "open_device", lambda *a: opened.append(a))
    path = tmp_path / "m.yaml"
    if content is not None:
        path.write_text(content, encoding="utf-8")

    def prompt(text):
        raise AssertionError("prompted for a bad mapping")

    with pytest.raises(MappingError) as info:
        calibrate(path, prompt=prompt, out=io.StringIO())
    assert str(path) in str(info.value)
    if content is None:
        assert "cannot read the mapping" in str(info.value)
    else:
        assert "box" in str(info.value) and "not defined" in str(info.value)
    assert opened == []


def test_puppet_calibrate_reports_a_bad_mapping_in_one_line(tmp_path, capsys):
    from puppet import cli

    assert cli.main(["calibrate", "--mapping", str(tmp_path / "missing.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("puppet calibrate: ") and "missing.yaml" in err


def test_a_device_name_the_mapping_does_not_have_is_refused_naming_the_ones_it_has(tmp_path):
    mapping = tmp_path / "m.yaml"
    mapping.write_bytes(shipped_mappings()["arduino_sliders"].read_bytes())
    with pytest.raises(MappingError, match="no device named 'pad'.*devices: box"):
        calibrate(mapping, urls={"pad": "sim://joystick"}, prompt=lambda _: None, out=io.StringIO())


def test_an_absent_port_is_refused_with_the_reason_and_the_mapping_is_untouched(tmp_path, capsys):
    mapping = tmp_path / "m.yaml"
    mapping.write_bytes(shipped_mappings()["arduino_sliders"].read_bytes())
    before = mapping.read_bytes()
    assert main(["calibrate", "--mapping", str(mapping), "--device", "box=serial:///dev/no-such-port"]) == 2
    err = capsys.readouterr().err
    assert "not open" in err and "/dev/no-such-port" in err and "No such file" in err
    assert mapping.read_bytes() == before and not (tmp_path / "m.yaml.bak").exists()


def test_a_shipped_mapping_is_not_calibrated_in_place(capsys):
    assert main(["calibrate", "--mapping", "gamepad_hid"]) == 2
    assert "puppet mappings --copy gamepad_hid" in capsys.readouterr().err


@pytest.mark.slow
def test_puppet_calibrate_succeeds_against_the_simulated_joystick(tmp_path, monkeypatch, capsys):
    """No hardware: sim://joystick?motion=calibrate rests (off mid-scale, with ADC noise), then
    sweeps; the user's two Enters come from stdin."""
    mapping = tmp_path / "m.yaml"
    mapping.write_bytes(shipped_mappings()["arduino_sliders"].read_bytes())
    monkeypatch.setattr("sys.stdin", io.StringIO("\n\n"))
    assert main(["calibrate", "--mapping", str(mapping), "--rest", "1", "--sweep", "5",
                 "--device", "box=sim://joystick?motion=calibrate&rest=1.5&rate=200"]) == 0
    assert "Wrote 6 channel(s)" in capsys.readouterr().out
    load_mapping(mapping)
    channels = yaml.safe_load(mapping.read_text("utf-8"))["channels"]
    centres = set()
    for i in range(6):
        raw = channels[f"box.ch{i}"]
        assert raw["min"] < 60 and raw["max"] > 960  # swept end to end, short of the rails
        assert all(isinstance(raw[key], int) for key in ("min", "centre", "max") if key in raw)  # 10-bit counts
        if "centre" in raw:
            assert abs(raw["centre"] - 512) <= 35 and raw["centre"] != 512  # the rest, off mid-scale
            centres.add(raw["centre"])
    assert len(centres) >= 2


def test_the_simulated_joysticks_calibration_motion_rests_with_adc_noise_then_sweeps():
    from devices.simulated_serial import rest_then_sweep

    signal = rest_then_sweep(channels=3, rest_seconds=2.0, seed=7)
    rest = [signal(t / 200) for t in range(400)]
    sweep = [signal(2 + t / 200) for t in range(1600)]
    for i in range(3):
        at_rest = [r[i] for r in rest]
        assert 1 <= max(at_rest) - min(at_rest) <= 12 and all(v == int(v) for v in at_rest)  # whole counts, noisy
        swept = [s[i] for s in sweep]
        assert min(swept) < 30 and max(swept) > 990 and 0 <= min(swept) and max(swept) <= 1023


@pytest.mark.parametrize("url, message", [("sim://joystick?motion=wiggle", "motion=wiggle: expected sines, or calibrate"),
                                          ("sim://joystick?rest=2", "expected sines, or calibrate"),
                                          ("sim://joystick?motion=calibrate&rest=-1", "rest=-1: expected seconds")])
def test_a_bad_simulated_motion_is_refused(url, message):
    from devices import open_device
    from devices.base import DeviceError

    with pytest.raises(DeviceError, match=message):
        open_device(url, "box")


def test_a_count_or_two_of_jitter_after_a_rest_too_short_to_show_noise_is_not_a_sweep():
    """A 10-bit channel whose few rest readings were all alike (noise 0 seen) and that jitters by
    three counts in the sweep was never moved: a device in counts is never steadier than a count
    (a loaded machine's short rest phase once calibrated such a channel to 531..534)."""
    rest = {"still": [532.0] * 4, "swept": [512.0] * 4}
    sweep = {"still": [531.0, 533.0, 534.0, 532.0], "swept": [3.0, 512.0, 1020.0]}
    _, updates, warnings = cal._analyse({"still": False, "swept": False}, rest, sweep)
    assert list(updates) == ["swept"]
    assert any(w.startswith("still: never moved more in the sweep") for w in warnings)
