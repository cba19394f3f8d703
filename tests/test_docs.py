"""The user guide (docs/): it builds with ``mkdocs build --strict``, its generated references
cover every subcommand, option and mapping key, every ``puppet`` command it shows exists with
the options it gives, and its samples that can run headless do what the guide says."""

from __future__ import annotations

import argparse
import html
import importlib.util
import json
import re
import shlex
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import can
import pytest
import yaml

from devices import BACKENDS, State, open_device
from devices.serial_wire import make_parser
from puppet import cli
from puppet.io.fapfile import read_fap
from puppet.io.shipped import shipped_mapping
from puppet.io.takes import open_take
from puppet.live.mappingfile import load_mapping

ROOT = Path(__file__).resolve().parent.parent
GUIDE = ROOT / "docs" / "guide"
SAMPLES = GUIDE / "samples"
LIVE_LINK_HEADER_START = ["Timecode", "BlendShapeCount", "EyeBlinkLeft", "EyeLookDownLeft"]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The guide built strictly (any warning fails) into a temporary folder."""
    pytest.importorskip("mkdocs", reason="mkdocs is not installed (pip install '.[docs]')")
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "docs" / "mkdocs.yml"),
                           "-d", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return out


def page_text(site: Path, page: str) -> str:
    """A built page's text, tags dropped and entities decoded."""
    return html.unescape(re.sub(r"<[^>]+>", "", (site / page / "index.html").read_text("utf-8")))


def subparsers() -> dict[str, argparse.ArgumentParser]:
    """The ``puppet`` subcommands as the CLI builds them, caught as ``main`` adds them."""
    made: dict[str, argparse.ArgumentParser] = {}
    add = argparse._SubParsersAction.add_parser

    def record(self, name, **kwargs):
        made[name] = add(self, name, **kwargs)
        return made[name]

    argparse._SubParsersAction.add_parser = record
    try:
        with pytest.raises(SystemExit):
            cli.main(["--help"])
    finally:
        argparse._SubParsersAction.add_parser = add
    return made


def option_strings(parser: argparse.ArgumentParser) -> set[str]:
    return {s for action in parser._actions for s in action.option_strings}


def test_the_guide_builds_strictly(site):
    for page in ("getting-started", "devices/serial", "devices/hid", "devices/can", "devices/midi", "devices/osc",
                 "devices/simulated", "mappings", "takes", "faces", "arkit", "troubleshooting", "reference/mapping",
                 "reference/commands", "reference/faps", "reference/feature-points"):
        assert (site / page / "index.html").is_file(), page
    assert (site / "live_cockpit.png").read_bytes() == (GUIDE / "live_cockpit.png").read_bytes()  # getting started shows it
    for sample in ("livelink_sample.csv", "send_vmc.py", "slider_box.ino"):
        assert (site / "samples" / sample).read_bytes() == (SAMPLES / sample).read_bytes()


def test_the_command_reference_has_every_subcommand_and_option(site):
    text = page_text(site, "reference/commands")
    commands = subparsers()
    assert len(commands) >= 10
    for name, parser in commands.items():
        section = text.split(f"puppet {name}¶", 1)
        assert len(section) == 2, f"no section for puppet {name}"
        body = section[1].split("¶", 1)[0]
        for option in option_strings(parser):
            assert option in body, f"puppet {name} {option} is missing from its section"


def test_the_mapping_reference_has_every_schema_key(site):
    schema = json.loads((ROOT / "mappings" / "schema.json").read_text("utf-8"))
    text = page_text(site, "reference/mapping")
    keys = set(schema["properties"])
    for definition in schema["$defs"].values():
        keys |= set(definition.get("properties", {}))
        for part in definition.get("allOf", []):
            keys |= set(part.get("then", {}).get("properties", {}))
    assert {"devices", "channels", "targets", "smoothing", "min_cutoff", "tau", "points", "combine"} <= keys
    for key in keys:
        assert re.search(rf"(?<![\w.-]){re.escape(key)}(?![\w-])", text), f"schema key {key!r} is not in the reference"
    for name in schema["$defs"]:
        assert f"{name}¶" in text, f"no section for $defs/{name}"
    for value in schema["$defs"]["curve"]["properties"]["type"]["enum"]:
        assert f"type: {value}" in text


def guide_commands() -> list[tuple[str, str]]:
    """``(page, command line)`` for every ``puppet ...`` line of a shell block and every
    ``puppet ...`` in inline code, continuation lines joined and comments dropped."""
    found = []
    for page in sorted(GUIDE.rglob("*.md")):
        text = page.read_text("utf-8")
        for block in re.findall(r"```sh\n(.*?)```", text, re.S):
            for line in block.replace("\\\n", " ").splitlines():
                line = line.split(" #", 1)[0].strip()
                if line.startswith("puppet "):
                    found.append((page.name, line))
        for span in re.findall(r"`(puppet [a-z][a-z-]*(?: [^`]*)?)`", text):  # not messages: `puppet live: ...`
            found.append((page.name, span))
    return found


def test_every_command_in_the_guide_exists_with_its_options():
    commands = subparsers()
    lines = guide_commands()
    assert len(lines) > 40
    for page, line in lines:
        words = shlex.split(line)
        assert words[1] in commands, f"{page}: {line!r}: no subcommand {words[1]!r}"
        known = option_strings(commands[words[1]])
        for word in words[2:]:
            if word.startswith("-") and not re.fullmatch(r"-\d.*", word):
                assert word.split("=", 1)[0] in known, f"{page}: {line!r}: puppet {words[1]} has no {word}"


def test_every_device_backend_has_a_page_with_its_options():
    text = "\n".join(p.read_text("utf-8") for p in (GUIDE / "devices").glob("*.md"))
    for scheme in BACKENDS:
        assert f"<!-- url-options: {scheme} -->" in text, f"no device page lists the options of {scheme}://"
        assert f"{scheme}://" in text


def test_the_live_link_face_sample_imports_replays_and_exports(tmp_path, capsys):
    sample = SAMPLES / "livelink_sample.csv"
    header = sample.read_text("utf-8").splitlines()[0].split(",")
    assert header[:4] == LIVE_LINK_HEADER_START and len(header) == 63
    mapped = {c.split(".", 1)[1] for c in yaml.safe_load(shipped_mapping("arkit_csv").read_text("utf-8"))["channels"]}
    assert mapped <= set(header), "the sample lacks columns the shipped mapping reads"

    assert cli.main(["import-arkit", str(sample), "--takes", str(tmp_path / "takes")]) == 0
    folder = tmp_path / "takes" / "arkit_001"
    assert capsys.readouterr().out.strip() == str(folder)
    take = open_take(folder)
    assert take.meta["frames"] == 30 and take.meta["complete"]
    jaw = read_fap(folder / "take.fap").values[:, 2]
    assert jaw.max() > 100 and jaw[0] < jaw.max() and jaw[-1] < jaw.max()  # the jaw opens and closes

    again = tmp_path / "again.fap"
    assert cli.main(["replay", str(folder), "-o", str(again), "--no-window"]) == 0
    assert "identical to the recorded take.fap" in capsys.readouterr().out
    assert cli.main(["export", str(folder), "-o", str(tmp_path / "arkit.glb")]) == 0
    assert (tmp_path / "arkit.glb").read_bytes()[:4] == b"glTF"


def test_the_vmc_sender_drives_the_arkit_osc_mapping():
    spec = importlib.util.spec_from_file_location("send_vmc", SAMPLES / "send_vmc.py")
    sender = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sender)
    mapping = load_mapping(shipped_mapping("arkit_osc"))
    with open_device("osc://127.0.0.1:0", "phone") as phone:
        assert phone.wait_state(State.OPEN)
        sent = sender.send(str(SAMPLES / "livelink_sample.csv"), "127.0.0.1", phone.address[1], fps=200)  # paced: UDP drops a flood on a busy machine
        samples = []
        deadline = time.monotonic() + 10
        while len(samples) < sent and time.monotonic() < deadline:
            samples += phone.drain()
            time.sleep(0.01)
    assert sent == 60 and len(samples) == 60 and phone.counters.bad_frames == 0
    mapped = {c.split(".", 1)[1] for c in yaml.safe_load(shipped_mapping("arkit_osc").read_text("utf-8"))["channels"]}
    jaw = []
    for sample in samples:
        assert {"JawOpen", "EyeBlink_L", "MouthSmile_R"} <= set(sample.values)
        assert set(sample.values) - mapped <= {"TongueOut"}  # every other shape the tracker sends is mapped
        mapping.feed(sample)
        jaw.append(mapping.pose(sample.t_ns).fap[2])
    assert max(jaw) > 100 and jaw[0] < max(jaw) and jaw[-1] < max(jaw)


def test_the_arduino_sketch_sends_what_arduino_sliders_reads():
    sketch = (SAMPLES / "slider_box.ino").read_text("utf-8")
    pins = re.search(r"PINS\[\] = \{([^}]*)\}", sketch).group(1).split(",")
    assert "Serial.begin(115200)" in sketch and "Serial.println()" in sketch
    line = ",".join(str(100 * i + 12) for i in range(len(pins))) + "\r\n"  # what loop() prints
    readings = make_parser("ascii").feed(line.encode("ascii"))
    channels = {c.split(".", 1)[1] for c in yaml.safe_load(shipped_mapping("arduino_sliders").read_text("utf-8"))["channels"]}
    assert len(readings) == 1 and set(readings[0]) == channels


def test_the_cansend_lines_move_what_the_can_page_says():
    mapping = yaml.safe_load(shipped_mapping("can_joystick").read_text("utf-8"))
    signals = mapping["devices"]["stick"]["options"]["signals"]
    text = (GUIDE / "devices" / "can.md").read_text("utf-8")
    frames = {payload: (name, float(value)) for payload, name, value in
              re.findall(r"cansend vcan0 100#([0-9A-F]{16})\s+# (\w+) ([\d.]+) %", text)}
    assert {name for name, _ in frames.values()} == {"Throttle", "JoystickX"}
    channel = f"docs-{time.monotonic_ns()}"
    with open_device(f"can://virtual/{channel}?signals={signals}", "stick") as stick, \
            can.Bus(interface="virtual", channel=channel) as bus:
        assert stick.wait_state(State.OPEN)
        for payload in frames:
            bus.send(can.Message(arbitration_id=0x100, data=bytes.fromhex(payload), is_extended_id=False))
        readings = []
        deadline = time.monotonic() + 5
        while len(readings) < len(frames) and time.monotonic() < deadline:
            readings += [s.values for s in stick.drain()]
            time.sleep(0.01)
    assert len(readings) == len(frames)
    for (name, value), reading in zip(frames.values(), readings):
        assert reading[name] == pytest.approx(value)


def test_every_python_name_the_schema_and_the_guide_cite_exists():
    """The mapping reference (made from mappings/schema.json) and the guide's pages name Python
    objects, e.g. where the muscle names live (``puppet.face.muscles.MUSCLE_NAMES``, once cited as
    ``puppet.muscles.MUSCLE_NAMES``); each must import."""
    import importlib

    sources = [ROOT / "mappings" / "schema.json", *sorted(GUIDE.rglob("*.md"))]
    name = re.compile(r"\b((?:puppet|devices)(?:\.[a-z_]+)+)\.([A-Z][A-Z_]+)\b")
    cited = {(m, n, path.name) for path in sources for m, n in name.findall(path.read_text("utf-8"))}
    assert any(source == "schema.json" for *_, source in cited)
    for module, name, source in cited:
        assert hasattr(importlib.import_module(module), name), f"{source} cites {module}.{name}"


def _hooks():
    """docs/hooks.py as a module: the generator of the guide's pages made from the code."""
    spec = importlib.util.spec_from_file_location("guide_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_pages_made_from_the_code_are_committed_as_it_makes_them():
    """reference/*.md are in the tree (the guide's links work unbuilt) and are what the code makes
    today: after changing the CLI, the schema, the FAP table or the default rig, regenerate them."""
    hooks = _hooks()
    for name, text in hooks.generated_pages().items():
        path = GUIDE / name
        assert path.is_file(), f"docs/guide/{name} is missing: run `python docs/hooks.py` and commit it"
        made_by = re.search(rf"{hooks.HELP_PYTHON}(\d+\.\d+)", path.read_text("utf-8"))
        if made_by and made_by.group(1) != f"{sys.version_info.major}.{sys.version_info.minor}":
            continue  # another Python's argparse words the help otherwise; the site tests check its contents
        assert path.read_text("utf-8") == text, \
            f"docs/guide/{name} is not what the code makes: run `python docs/hooks.py` and commit it"


def test_the_fap_glossary_gives_every_fap_its_unit_and_the_default_face_s_reach():
    from puppet.face.default import load_default_rig
    from puppet.fap.table import faps

    text = (GUIDE / "reference" / "faps.md").read_text("utf-8")
    row = re.compile(r"^\| (\d+) \| `\w+` \| (.*) \|$", re.M)
    rows = {int(m.group(1)): m.group(2).split(" | ") for m in row.finditer(text)}
    assert sorted(rows) == list(range(1, 69))
    reach = load_default_rig().fap_reach
    for fap in faps():
        what, unit, positive, shown = rows[fap.number]
        assert fap.description.rstrip(".") in what and unit == (fap.unit or "").removesuffix("0")
        if fap.unit is None:
            continue
        assert positive.startswith(fap.direction), (fap.name, positive)
        if fap.number not in reach:
            assert shown == "none", (fap.name, shown)
        else:
            ends = [float("-inf") if e == "none" and i == 0 else float("inf") if e == "none" else float(e)
                    for i, e in enumerate(shown.split(" to "))]
            assert ends == pytest.approx(list(reach[fap.number]), abs=0.051), (fap.name, shown)


def test_the_feature_point_page_lists_what_rig_needs_with_its_picture():
    from puppet.face.landmarks import FDP_NEEDED

    text = (GUIDE / "reference" / "feature-points.md").read_text("utf-8")
    listed = re.findall(r"^\| (\d+\.\d+) \| \w", text, re.M)
    assert sorted(listed) == sorted(FDP_NEEDED) and len(listed) == len(set(listed))
    assert f"these {len(FDP_NEEDED)} MPEG-4 feature points" in text
    assert "(../feature_points.png)" in text and (GUIDE / "feature_points.png").is_file()
    assert "reference/feature-points.md" in (GUIDE / "faces.md").read_text("utf-8")


def test_the_version_is_the_same_in_pyproject_the_cli_and_the_changelog(capsys):
    version = tomllib.loads((ROOT / "pyproject.toml").read_text("utf-8"))["project"]["version"]
    with pytest.raises(SystemExit):
        cli.main(["--version"])
    assert capsys.readouterr().out.split()[-1] == version
    released = re.findall(r"^## \[(\d+\.\d+\.\d+)\]", (ROOT / "CHANGELOG.md").read_text("utf-8"), re.MULTILINE)
    assert released and released[0] == version, "CHANGELOG.md's newest version is not pyproject's"


def test_the_readme_is_a_short_front_page_whose_links_and_picture_exist():
    text = (ROOT / "README.md").read_text("utf-8")
    assert len(text.splitlines()) <= 150
    assert "bash tools/demo.sh" in text and "bash tools/test.sh" in text
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert "docs/readme.gif" in links and len(links) > 10
    for link in links:
        if not link.startswith("http"):
            assert (ROOT / link).exists(), f"README.md links to {link}, which is not there"
    assert (ROOT / "docs" / "readme.gif").stat().st_size < 1_500_000
