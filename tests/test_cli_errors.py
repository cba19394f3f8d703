"""Every bad invocation is one line on stderr and exit code 2, never a traceback, and is refused
before anything is written or a window opens (the table below: what a new user types wrong)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

from puppet import cli
from puppet.live.arkit import import_csv
from puppet.view import window

ROOT = Path(__file__).resolve().parents[1]
MAPPING = str(ROOT / "mappings" / "arduino_sliders.yaml")


@pytest.fixture(scope="module")
def place(tmp_path_factory) -> dict[str, str]:
    """A good take, damaged takes and bad files to name in the invocations."""
    root = tmp_path_factory.mktemp("cli")
    csv = root / "face.csv"
    csv.write_text("Timecode,BlendShapeCount,JawOpen\n"
                   + "".join(f"00:00:00:{i:02d}.000,1,{i / 20:.2f}\n" for i in range(20)))
    take = import_csv(csv, root / "takes", "good", fps=30)
    listed = root / "takes" / "listed_001"
    listed.mkdir()
    (listed / "take.json").write_text("[]")
    (root / "binary.fap").write_bytes(bytes(range(256)) * 4)
    (root / "bad.yaml").write_text("devices: {box: 'sim://joystick'}\nchannels: [[[\n")
    (root / "photo.png").write_bytes(b"not a png")
    Image.new("RGB", (64, 48), (200, 160, 140)).save(root / "face.png")  # a photo that opens
    (root / "mesh.obj").write_text("v 0 0 0\nf 1 2 3\n")
    (root / "folder").mkdir()
    (root / "header_only.csv").write_text("Timecode,BlendShapeCount,JawOpen\n")
    return {"take": str(take), "listed": str(listed), "tmp": str(root), "csv": str(csv),
            "binary": str(root / "binary.fap"), "bad_yaml": str(root / "bad.yaml"),
            "photo": str(root / "photo.png"), "real_photo": str(root / "face.png"), "mesh": str(root / "mesh.obj"),
            "folder": str(root / "folder"), "header_only": str(root / "header_only.csv")}


BAD = [
    "", "nonsense", "render", "render {take} {take}",
    "render {take} -o {tmp}/x.mp4 --fps inf", "render {take} -o {tmp}/x.mp4 --fps nan",
    "render {take} -o {tmp}/x.mp4 --fps 1e-300", "render {take} -o {tmp}/x.mp4 --fps abc",
    "render {take} -o {tmp}/x.mp4 --size 99999x99999", "render {take} -o {tmp}/x.mp4 --size 1x1",
    "render {take} -o {tmp}/x.mp4 --size big", "render {take} -o /nonexistent/dir/x.mp4",
    "render {take} {take} -o {tmp}/videos/", "render {take} -o {tmp}/x.mp4 --view top",
    "render {take} -o {tmp}/x.mp4 --face /nonexistent.obj", "render {take} -o {tmp}/x.mp4 --face {mesh}",
    "render {binary} -o {tmp}/x.mp4", "render /nonexistent.fap -o {tmp}/x.mp4",
    "render {listed} -o {tmp}/x.mp4", "render {tmp} -o {tmp}/x.mp4",
    "replay {take} -o /nonexistent/dir/x.fap --no-window", "replay {take} -o {folder} --no-window",
    "replay {take} -o {take}/take.fap --no-window", "replay {listed} -o {tmp}/r.fap --no-window",
    "replay {take} --mapping {bad_yaml} --no-window", "replay {take} --mapping /nonexistent.yaml --no-window",
    "replay /nonexistent -o {tmp}/r.fap --no-window",
    "export {take}", "export {take} -o /nonexistent/x.glb", "export {take} -o {tmp}/x.glb --max-frames 0",
    "export {take} -o {tmp}/x.glb --mode bones", "export {binary} -o {tmp}/x.glb",
    "import-arkit {csv} --name bad_name! --takes {tmp}/t", "import-arkit {csv} --name '' --takes {tmp}/t",
    "import-arkit /nonexistent.csv --takes {tmp}/t", "import-arkit {photo} --takes {tmp}/t",
    "import-arkit {csv} --fps 24 --takes {tmp}/t", "import-arkit {csv} --csv-fps 0 --takes {tmp}/t",
    "import-arkit {csv} --mapping {bad_yaml} --takes {tmp}/t",
    "calibrate --mapping /nonexistent.yaml", "calibrate --mapping {bad_yaml}",
    "calibrate --mapping {mapping} --rest -1", "calibrate --mapping {mapping} --sweep 1e300",
    "pick-landmarks {real_photo} -o {tmp}/p.json --port 99999 --no-browser",
    "pick-landmarks {photo} -o {tmp}/p.json --no-browser",
    "pick-landmarks {photo} -o /nonexistent/p.json --no-browser",
    "rig {mesh} --landmarks /nonexistent.json -o {tmp}/r.rig", "rig /nonexistent.obj --landmarks x -o {tmp}/r.rig",
    "rig {mesh} --landmarks x -o /nonexistent/r.rig", "rig {mesh} -o {tmp}/r.rig", "rig {mesh} -o {tmp}/me",
    "rig /nonexistent.obj -o {tmp}/me", "pick-landmarks {mesh} -o {tmp}/p.json --no-browser",
    "pick-landmarks {mesh} --start /nonexistent.json -o {tmp}/p.json --no-browser",
    "face-from-photo {photo} --landmarks x -o {tmp}/me", "face-from-photo /nonexistent.png --landmarks x -o {tmp}/me",
    "calibrate-face --examples /nonexistent -o {tmp}/c.rig", "calibrate-face --examples {folder} -o {tmp}/c.rig",
    "calibrate-face --examples {tmp} -o {tmp}/c.rig", "calibrate-face --examples {folder} -o /nonexistent/c.rig",
    "calibrate-face --examples {folder} -o {tmp}/c.rig --face {mesh}",
    "bench --frames 0", "bench --flood-seconds inf", "bench --flood-rate 0", "demo --size 1x1",
    "live", "live --mapping /nonexistent.yaml", "live --mapping {bad_yaml}", "live --mapping {mapping} --fps 24",
    "live --mapping {mapping} --device nonsense", "live --mapping {mapping} --layer-over {take}",
    "play /nonexistent.fap", "play {binary}", "play {listed}", "play {take} --size 99999x99999",
    "live --mapping {mapping} --arm box.ch0", "live --mapping {mapping} --record 'bad name!'",
    "import-arkit {header_only} --takes {tmp}/t", "replay {take} --mapping {folder} --no-window",
]

WITH_A_DISPLAY = [
    "play /nonexistent.fap", "play {binary}", "play {listed}", "play {take} --face /nonexistent.obj",
    "play {take} --face {mesh}",
    "live --mapping /nonexistent.yaml", "live --mapping {bad_yaml}",
    "live --mapping {mapping_typo}",
    "live --mapping {mapping} --device box=sim://joystik",
    "live --mapping {mapping} --device box=sim://joystick --face /nonexistent.obj",
    "live --mapping {mapping} --device box=sim://joystick --layer-over /nonexistent.fap --arm box.ch0",
    "live --mapping {mapping} --device box=sim://joystick --layer-over {take} --arm box.ch9",
    "live --mapping {mapping} --device box=sim://joystick --layer-over {take} --arm nothing",
    "live --mapping {mapping} --device box=sim://joystick --record 'bad name!'",
]


def _argv(line: str, place: dict[str, str]) -> list[str]:
    import shlex

    names = {**place, "mapping": MAPPING, "mapping_typo": MAPPING.replace("sliders", "slidrs")}
    return [arg.format(**names) for arg in shlex.split(line)]


def _main(argv: list[str], capsys) -> tuple[int, str]:
    capsys.readouterr()
    try:
        code = cli.main(argv)
    except SystemExit as exit_:
        code = exit_.code
    return code, capsys.readouterr().err


def _one_clear_line(code: int, err: str) -> None:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("puppet"), (code, err)
    assert "Traceback" not in err and "_positive" not in err and "invalid int value" not in err


@pytest.mark.parametrize("line", BAD)
def test_a_bad_invocation_is_one_line_and_exit_code_2(line, place, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    before = sorted(os.listdir(place["tmp"]))
    _one_clear_line(*_main(_argv(line, place), capsys))
    assert sorted(os.listdir(place["tmp"])) == before  # nothing written beside the inputs


@pytest.mark.parametrize("line", WITH_A_DISPLAY)
def test_with_a_display_bad_input_is_refused_before_the_window_opens(line, place, capsys, monkeypatch):
    monkeypatch.setenv("DISPLAY", ":99")
    opened = []
    monkeypatch.setattr(window, "open_window", lambda *a, **k: opened.append(a) or pytest.fail("window opened"))
    import puppet.view.livewindow

    monkeypatch.setattr(puppet.view.livewindow, "open_window", lambda *a, **k: opened.append(a) or pytest.fail("window opened"))
    _one_clear_line(*_main(_argv(line, place), capsys))
    assert not opened


ON_XVFB = """
import contextlib, io, json, sys
from puppet import cli
for argv in json.loads(sys.argv[1]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            code = cli.main(argv)
        except SystemExit as exit_:
            code = exit_.code
    print(json.dumps([argv, code, err.getvalue()]), flush=True)
"""


def test_on_a_real_display_bad_input_is_refused_before_a_window_opens(place):
    """The same invocations under Xvfb with the real window code: one that got past its checks
    would open a window and wait there (the timeout)."""
    import json
    import shutil

    if shutil.which("xvfb-run") is None:
        pytest.skip("no xvfb-run here (tools/setup.sh installs xvfb where it can)")
    argvs = [_argv(line, place) for line in WITH_A_DISPLAY]
    run = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", ON_XVFB, json.dumps(argvs)], capture_output=True,
                         text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=place["tmp"], timeout=300)
    results = [json.loads(line) for line in run.stdout.splitlines() if line.startswith("[")]
    assert len(results) == len(argvs), run.stdout + run.stderr
    for _, code, err in results:
        _one_clear_line(code, err)


@pytest.mark.parametrize("line", ["render {take} -o /nonexistent/dir/x.mp4", "replay {listed} -o {tmp}/r.fap",
                                  "pick-landmarks {real_photo} -o {tmp}/p.json --port 99999",
                                  "import-arkit {csv} --name 'bad name!' --takes {tmp}/t"])
def test_a_real_process_prints_one_line(line, place):
    run = subprocess.run([sys.executable, "-m", "puppet.cli", *_argv(line, place)], capture_output=True,
                         text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, stdin=subprocess.DEVNULL,
                         timeout=120)
    _one_clear_line(run.returncode, run.stderr)
    assert not run.stdout


def test_calibrate_with_stdin_closed_is_one_line(place, tmp_path):
    mapping = tmp_path / "m.yaml"
    mapping.write_text(Path(MAPPING).read_text())
    run = subprocess.run([sys.executable, "-m", "puppet.cli", "calibrate", "--mapping", str(mapping)],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
                         stdin=subprocess.DEVNULL, timeout=120)
    _one_clear_line(run.returncode, run.stderr)
    assert mapping.read_text() == Path(MAPPING).read_text()


def test_every_error_class_in_puppet_is_a_puppet_error_with_its_builtin_base():
    import importlib
    import pkgutil

    import puppet
    from puppet.errors import PuppetError

    found = {}
    for module in pkgutil.walk_packages(puppet.__path__, "puppet."):
        mod = importlib.import_module(module.name)
        for name, value in vars(mod).items():
            if isinstance(value, type) and issubclass(value, Exception) and value.__module__ == mod.__name__:
                found[name] = value
    assert {"CsvError", "CalibrationError", "PhotoFaceError", "ExampleError", "RigError", "WindowError",
            "SibsonError", "DffdError", "FapError", "FaceFileError", "MissingFeaturePointsError",
            "UnknownFapError", "LandmarkError", "TakeError", "OutputError"} <= set(found)
    for name, error in found.items():
        if name in ("PuppetError", "MappingError") or issubclass(error, Warning):  # MappingError: rebased
            continue
        assert issubclass(error, PuppetError), name
        builtin = [b for b in error.__mro__ if b.__module__ == "builtins" and b not in (Exception, BaseException, object)]
        assert builtin, f"{name} keeps no built-in base (ValueError, OSError ...)"


def test_the_view_choices_are_the_renderers_views():
    from puppet.view.renderer import ANTIALIAS_MODES, VIEW_DIRECTIONS

    assert cli.VIEWS == tuple(VIEW_DIRECTIONS)
    assert cli.ANTIALIAS_MODES == ANTIALIAS_MODES
