"""The shipped mappings are found by name from any folder, in a checkout and in an installed wheel."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from puppet.errors import PuppetError
from puppet.io.shipped import MappingExists, MappingNotFound, copy_mapping, mapping_path, shipped_mappings
from puppet.live.mappingfile import load_mapping

ROOT = Path(__file__).resolve().parents[1]


def test_every_shipped_mapping_is_listed_by_name_and_loads():
    shipped = shipped_mappings()
    assert {"arduino_sliders", "gamepad_hid", "can_joystick", "midi_faders", "arkit_csv", "arkit_osc"} <= set(shipped)
    for name, path in shipped.items():
        assert mapping_path(name) == path == mapping_path(f"{name}.yaml")
        load_mapping(path)


def test_a_path_that_exists_wins_over_a_shipped_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("arduino_sliders").write_text("mine")
    assert mapping_path("arduino_sliders") == Path("arduino_sliders")


def test_an_unknown_mapping_names_the_closest_shipped_one():
    with pytest.raises(MappingNotFound, match="did you mean 'arduino_sliders'") as caught:
        mapping_path("arduino_slider")
    assert isinstance(caught.value, PuppetError) and isinstance(caught.value, FileNotFoundError)


def test_a_copy_is_editable_and_never_overwrites(tmp_path):
    copy = copy_mapping("gamepad_hid", tmp_path)
    assert copy == tmp_path / "gamepad_hid.yaml"
    assert copy.read_bytes() == shipped_mappings()["gamepad_hid"].read_bytes()
    with pytest.raises(MappingExists):
        copy_mapping("gamepad_hid", tmp_path)


@pytest.mark.slow
def test_the_wheel_carries_the_mappings_and_data_and_finds_them_from_another_folder(tmp_path, egl):
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                    "-w", str(wheels), str(ROOT)], check=True, capture_output=True)
    wheel = next(wheels.glob("facepuppet-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    assert "puppet/mappings/arduino_sliders.yaml" in names and "puppet/data/default_face.npz" in names
    assert any(n.endswith("licenses/LICENSE") for n in names) and any(n.endswith("licenses/NOTICE.md") for n in names)
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, capture_output=True)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    probe = ("import puppet, puppet.io.shipped as s, puppet.live.arkit as a; "
             "print(puppet.__file__); print(s.mapping_path('arduino_sliders')); print(a.DEFAULT_MAPPING)")
    env = {**os.environ, "PYTHONPATH": str(site)}
    out = subprocess.run([sys.executable, "-c", probe], cwd=elsewhere, env=env, check=True,
                         capture_output=True, text=True).stdout.split()
    assert all(line.startswith(str(site)) for line in out), out

    def puppet(*args: str) -> str:  # the installed command, run from another folder
        done = subprocess.run([sys.executable, "-m", "puppet.cli", *args], cwd=elsewhere, env=env,
                              capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        return done.stdout

    sample = ROOT / "docs" / "guide" / "samples" / "livelink_sample.csv"
    assert puppet("import-arkit", str(sample)).strip() == str(Path("takes") / "arkit_001")
    assert "30 frames" in puppet("render", "takes/arkit_001", "--size", "160x120")  # no -o: into the take
    assert (elsewhere / "takes" / "arkit_001" / "take.mp4").stat().st_size > 0


def test_puppet_mappings_lists_and_copies_and_a_wrong_name_is_one_line(tmp_path, capsys):
    from puppet.cli import main

    assert main(["mappings"]) == 0
    listed = capsys.readouterr().out
    assert all(name in listed for name in shipped_mappings())
    assert main(["mappings", "--copy", "midi_faders", "-o", str(tmp_path)]) == 0
    assert (tmp_path / "midi_faders.yaml").exists()
    assert main(["mappings", "--copy", "midi_faders", "-o", str(tmp_path)]) == 2
    assert main(["calibrate", "--mapping", "midi_fader"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'midi_faders'" in err and "Traceback" not in err


def test_puppet_mappings_says_each_description_in_whole_words_in_one_column(capsys):
    """Each mapping's ``description:``, never cut mid-word (a long one ends at a word, with ...),
    every description starting in the same column however long the names."""
    import yaml

    from puppet.cli import _summary, main

    assert main(["mappings"]) == 0
    lines = capsys.readouterr().out.splitlines()[:-1]
    columns = {len(line) - len(line.split("  ", 1)[1].lstrip()) for line in lines}
    assert len(columns) == 1
    column = columns.pop()
    for line, (name, path) in zip(lines, shipped_mappings().items()):
        said = line[column:]
        whole = yaml.safe_load(path.read_text())["description"]
        assert line.startswith(name) and (said == whole or (said.endswith("...") and whole.startswith(said[:-3])
                                                             and whole[len(said) - 3] in " ,;:"))
    long = "word " * 40
    cut = _summary(f"description: {long}")
    assert len(cut) <= 90 and cut.endswith("word...")


def test_live_takes_go_where_takes_says(monkeypatch, tmp_path):
    import puppet.view.livewindow
    from puppet.cli import main

    seen = {}
    monkeypatch.setattr(puppet.view.livewindow, "run_live", lambda mapping, **kw: seen.update(kw, mapping=mapping))
    assert main(["live", "--mapping", "arduino_sliders", "--takes", str(tmp_path)]) == 0
    assert seen["record_root"] == str(tmp_path) and seen["mapping"] == str(shipped_mappings()["arduino_sliders"])
