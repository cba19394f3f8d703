"""Replaying a take's raw log: a live take (pulled plug, neutral key and all) comes back as the
identical .fap, through the mapping or through the devices' own wires; another mapping re-maps
it; a layered pass replaces only its armed FAPs."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from devices import State, open_device
from puppet.io.fapfile import read_fap
from puppet.io.takes import TakeError, open_take
from puppet.live.retake import retake
from puppet.live.session import LiveSession
from puppet.runtime.runtime import Runtime

ROOT = Path(__file__).resolve().parents[1]
MAPPING = ROOT / "mappings" / "arduino_sliders.yaml"
JOYSTICK = "sim://joystick?protocol=ascii&rate=200&channels=6"


@pytest.fixture(scope="module")
def shared_runtime(face):
    return Runtime(face)


def _session(runtime, root, **options):
    return LiveSession(MAPPING, face=runtime, devices={"box": open_device(JOYSTICK, "box")},
                       record_root=root, fps=30, **options)


def _frames_for(session, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        session.frame()
        time.sleep(0.01)


def _open(session):
    deadline = time.monotonic() + 5
    while not (all(s is State.OPEN for s in session.frame().states.values()) and session.samples_fed):
        assert time.monotonic() < deadline, "the simulated device never opened"
        time.sleep(0.01)


@pytest.fixture(scope="module")
def live_take(shared_runtime, tmp_path_factory):
    """A take of the simulated slider box with everything that can happen live: a start mid-motion,
    the plug pulled and put back, the neutral key, the brows re-centred."""
    session = _session(shared_runtime, tmp_path_factory.mktemp("takes"))
    try:
        _open(session)
        session.start_recording()
        _frames_for(session, 0.4)
        box = session.devices["box"]
        box.joystick.unplug()
        assert box.wait_state(State.LOST, 5.0)
        _frames_for(session, 0.2)
        box.joystick.replug()
        assert box.wait_state(State.OPEN, 5.0)
        _frames_for(session, 0.3)
        session.neutral()
        _frames_for(session, 0.15)
        session.recentre()
        _frames_for(session, 0.15)
        return open_take(session.stop_recording())
    finally:
        session.close()


def test_the_log_notes_the_gap_and_the_neutral_key(live_take):
    kinds = [getattr(e, "kind", "sample") for e in live_take.entries()]
    assert "hold" in kinds and "resume" in kinds and "reset" in kinds
    assert kinds.index("hold") < kinds.index("resume") < kinds.index("reset") < kinds.index("recentre")
    assert live_take.meta["frames"] >= 30 and live_take.meta["t0_ns"] > 0 and live_take.meta["complete"]


def test_a_live_take_replays_to_the_identical_fap(live_take, tmp_path):
    result = retake(live_take, tmp_path / "again.fap")
    assert result.identical, "the replayed .fap differs from the recorded one"
    assert result.frames == live_take.meta["frames"]


def test_another_mapping_re_maps_the_take(live_take, tmp_path):
    text = MAPPING.read_text().replace("{fap: open_jaw, source: box.ch0, range: [0, 700]}",
                                       "{fap: open_jaw, source: box.ch0, range: [0, 350]}")
    other = tmp_path / "half_jaw.yaml"
    other.write_text(text)
    result = retake(live_take, tmp_path / "remapped.fap", mapping=other)
    assert result.identical is None and result.frames == live_take.meta["frames"]
    original = live_take.stream().values
    remapped = read_fap(result.path).values
    jaw = 2  # FAP 3, open_jaw
    moving = original[:, jaw] > 20
    assert moving.any()
    assert np.all(remapped[moving, jaw] < original[moving, jaw])
    others = np.delete(np.arange(68), jaw)
    np.testing.assert_array_equal(remapped[:, others], original[:, others])  # the same channels, restored


def test_a_take_cannot_be_replayed_over_itself_or_without_its_state(live_take, tmp_path):
    with pytest.raises(TakeError, match="own .fap"):
        retake(live_take, live_take.fap_path)
    folder = tmp_path / "old_take"
    folder.mkdir()
    (folder / "take.json").write_text('{"name": "old", "fps": 30}')
    with pytest.raises(TakeError, match="t0_ns"):
        retake(folder, tmp_path / "x.fap")


def test_a_layered_pass_replaces_only_its_armed_faps(live_take, shared_runtime, tmp_path):
    session = _session(shared_runtime, tmp_path, layer_over=live_take.folder, arm=["box.ch0"])
    try:
        _open(session)
        session.start_recording()
        _frames_for(session, 0.5)
        layered = open_take(session.stop_recording())
    finally:
        session.close()
    base = live_take.stream().values
    new = layered.stream().values
    n = min(len(base), len(new))
    jaw = 2
    np.testing.assert_array_equal(np.delete(new[:n], jaw, axis=1)[:, 2:], np.delete(base[:n], jaw, axis=1)[:, 2:])
    assert not np.array_equal(new[:n, jaw], base[:n, jaw])
    assert layered.meta["layer"]["slots"] == [jaw]
    assert retake(layered, tmp_path / "layered_again.fap").identical


def test_arming_something_that_drives_nothing_is_refused(live_take, shared_runtime, tmp_path):
    with pytest.raises(TakeError, match="no channel 'box.ch9'"):  # one line in the CLI, not a KeyError
        _session(shared_runtime, tmp_path, layer_over=live_take.folder, arm=["box.ch9"])
    with pytest.raises(ValueError, match="FAP number"):
        _session(shared_runtime, tmp_path, layer_over=live_take.folder, arm=["jaw please"])


# -- recording faults ----------------------------------------------------------------------------

def test_an_unwritable_take_folder_is_a_clear_error_before_anything_is_written(shared_runtime, tmp_path):
    root = tmp_path / "locked"
    root.mkdir()
    root.chmod(0o500)
    if os.access(root, os.W_OK):  # root ignores permissions: use a path under a file instead
        root = tmp_path / "a_file" / "takes"
        root.parent.write_text("")
    session = _session(shared_runtime, root)
    try:
        _open(session)
        with pytest.raises(TakeError, match="cannot make a take folder"):
            session.start_recording()
        assert not session.recording
        session.frame()  # the live face goes on
    finally:
        session.close()


def test_a_full_disk_ends_the_take_marked_incomplete_and_the_face_goes_on(shared_runtime, tmp_path):
    session = _session(shared_runtime, tmp_path)
    try:
        _open(session)
        folder = session.start_recording()
        _frames_for(session, 0.3)
        recorder = session._recorder
        written = recorder.frames
        recorder._log.sync()  # the log's writer thread idle (nothing queued) while its file is swapped
        recorder._log._file.close()
        recorder._log._file = open("/dev/full", "w", encoding="utf-8")  # the kernel's own ENOSPC
        _frames_for(session, 0.2)
        assert not session.recording and "No space left on device" in session.record_error
        f = session.frame()
        assert f.vertices.shape == shared_runtime.rest.shape
    finally:
        session.close()
    take = open_take(folder)
    assert take.meta["complete"] is False and "No space left" in take.meta["error"]
    assert len(take.stream()) >= written > 0  # every frame written before the disk filled


# -- the command line ----------------------------------------------------------------------------

def test_puppet_replay_writes_and_checks_a_new_fap(live_take, tmp_path, capsys):
    from puppet import cli

    out = tmp_path / "cli.fap"
    assert cli.main(["replay", str(live_take.folder), "--through-devices", "-o", str(out), "--no-window"]) == 0
    assert capsys.readouterr().out.strip() == f"{out}: {live_take.meta['frames']} frames, identical to the recorded take.fap"
    assert cli.main(["replay", str(tmp_path / "nope"), "-o", str(out), "--no-window"]) == 2
    assert "nope: no such take folder" in capsys.readouterr().err


def test_an_imported_arkit_take_can_be_re_mapped(tmp_path):
    from puppet.live.arkit import DEFAULT_MAPPING, import_csv

    names = ["JawOpen", "MouthSmileLeft", "MouthSmileRight", "BrowInnerUp"]
    rows = [f"00:00:00:{i:02d}.000,4," + ",".join(f"{(i * (k + 1) % 17) / 16:.4f}" for k in range(4))
            for i in range(40)]
    csv = tmp_path / "face.csv"
    csv.write_text("Timecode,BlendShapeCount," + ",".join(names) + "\n" + "\n".join(rows) + "\n")
    folder = import_csv(csv, tmp_path / "takes", fps=30)
    assert retake(folder, tmp_path / "again.fap").identical
    stronger = tmp_path / "stronger.yaml"
    stronger.write_text(DEFAULT_MAPPING.read_text())
    remapped = retake(folder, tmp_path / "remap.fap", mapping=stronger)
    np.testing.assert_array_equal(read_fap(remapped.path).values, open_take(folder).stream().values)


def test_a_live_take_replays_through_the_real_serial_adapter_to_the_identical_fap(live_take, tmp_path):
    assert live_take.meta["devices"]["box"] == JOYSTICK
    result = retake(live_take, tmp_path / "wire.fap", through_devices=True)
    assert result.identical, "the .fap replayed through the pty and the serial adapter differs"


# -- record, replay through the devices' wires: HID and CAN ------------------------------------------

def _record(session, seconds=0.6):
    _open(session)
    session.start_recording()
    _frames_for(session, seconds)
    return open_take(session.stop_recording())


def test_a_hid_gamepad_take_replays_through_hid_reports_to_the_identical_fap(shared_runtime, tmp_path):
    from devices.base import Url
    from devices.hid_device import HidDevice
    from devices.simulated_hid import FakeHidModule, gamepad, gamepad_motion

    url = "hid://046d:c21d"
    pad = HidDevice.from_url(Url.parse(url), "pad", hid_module=FakeHidModule(gamepad(gamepad_motion(), rate=250)))
    pad.url = url  # as open_device names it
    session = LiveSession(ROOT / "mappings" / "gamepad_hid.yaml", face=shared_runtime, devices={"pad": pad},
                          record_root=tmp_path, fps=30)
    try:
        take = _record(session)
    finally:
        session.close()
    assert take.meta["wire"]["pad"]["report_descriptor"]
    assert retake(take, tmp_path / "wire.fap", through_devices=True).identical


def test_a_can_joystick_take_replays_through_can_frames_to_the_identical_fap(shared_runtime, tmp_path):
    import uuid

    from devices.simulated_can import CanJoystick
    from puppet.live.mappingfile import load_mapping

    channel = f"replay-{uuid.uuid4().hex[:8]}"
    mapping_url = load_mapping(ROOT / "mappings" / "can_joystick.yaml").devices["stick"]
    url = mapping_url.replace("virtual/vcan0", f"virtual/{channel}")
    with CanJoystick(channel, rate=200):
        session = LiveSession(ROOT / "mappings" / "can_joystick.yaml", face=shared_runtime,
                              devices={"stick": open_device(url, "stick")}, record_root=tmp_path, fps=30)
        try:
            take = _record(session)
        finally:
            session.close()
    assert take.meta["samples"] > 50
    assert retake(take, tmp_path / "wire.fap", through_devices=True).identical


def test_a_layered_pass_says_its_base_take_where_it_is_and_what_is_armed(live_take, shared_runtime, tmp_path):
    """What the cockpit shows under REC for a layered pass: the base take playing under it, its
    frame now, and what the pass replaces; a session without a layer says nothing."""
    session = _session(shared_runtime, tmp_path, layer_over=live_take.folder, arm=["box.ch0", "viseme"])
    try:
        _open(session)
        total = live_take.meta["frames"]
        length = f"0:{total / live_take.meta['fps']:05.2f}"
        assert session.layer_status() == (f"over {live_take.folder.name}, frame 1 of {total} (0:00.00 of {length}); "
                                          "armed: open_jaw, viseme")
        start = time.monotonic_ns()
        session.start_recording(start)
        assert session.layer_status(start + 500_000_000) == (f"over {live_take.folder.name}, frame 16 of {total} "
                                                             f"(0:00.50 of {length}); armed: open_jaw, viseme")
        session.stop_recording()
    finally:
        session.close()
    plain = _session(shared_runtime, tmp_path)
    try:
        assert plain.layer_status() is None
    finally:
        plain.close()
