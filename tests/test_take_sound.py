"""Every take keeps its sound: recorded beside the .fap on the Samples' clock, whole after a kill,
in the rendered video at the right frame, replayed through wav:// into the same frames, played
in step (or silent, saying why), and made offline from a recording by ``puppet lipsync``."""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile
from test_voice import RATE, episodes, vowel, write_wav

from devices import open_device
from devices.soundread import read_sound
from devices.wav_device import WavDevice
from puppet.cli import main
from puppet.fap.held import held_low_level
from puppet.fap.highlevel import high_level_faps
from puppet.fap.table import faps
from puppet.io.fapfile import iter_fap, read_fap
from puppet.io.shipped import shipped_mapping
from puppet.io.soundtrack import Soundtrack, soundtrack
from puppet.io.takes import open_take
from puppet.io.wavwriter import WavWriter
from puppet.live.lipsync import MOUTH_GROUPS, lipsync
from puppet.live.retake import retake
from puppet.live.session import LiveSession
from puppet.view.demo import demo_speech, demo_take
from puppet.view.soundout import ClockedSound

ROOT = Path(__file__).resolve().parents[1]


def speech(tmp_path: Path, seconds: float = 1.6) -> Path:
    """Three vowels with a stop and a pause between them."""
    parts = [np.zeros(int(0.2 * RATE)), vowel(750, 1200), np.zeros(int(0.06 * RATE)), vowel(280, 2350),
             np.zeros(int(0.3 * RATE)), vowel(300, 750)]
    sound = np.concatenate(parts)
    rest = np.zeros(max(0, int(seconds * RATE) - len(sound)))
    return write_wav(tmp_path / "speech.wav", np.concatenate([sound, rest]))


def record(tmp_path: Path, wav: Path, *, wait_s: float = 0.3) -> tuple[Path, WavDevice]:
    """A live session on voice.yaml whose microphone plays ``wav``: recording starts ``wait_s``
    into the sound and stops at its end."""
    mic = open_device(f"wav://{wav}", "mic")
    with LiveSession(shipped_mapping("voice"), devices={"mic": mic}, record_root=tmp_path / "takes") as session:
        session.normals = False
        start = time.monotonic()
        while time.monotonic() - start < wait_s:
            session.wait_for_input(0.05)
            session.frame()
        session.start_recording()
        while not mic.finished:
            session.wait_for_input(0.05)
            session.frame()
        session.frame()
        return session.stop_recording(), mic


def test_a_take_keeps_its_sound_on_the_samples_clock_and_replays_through_wav_into_the_same_frames(tmp_path):
    wav = speech(tmp_path)
    folder, mic = record(tmp_path, wav)
    take = open_take(folder)
    [sound] = take.sounds()
    assert sound.path == folder / "take.wav" and sound.rate == RATE and take.meta["complete"]
    recorded, _ = read_sound(sound.path)
    original, _ = read_sound(wav)
    offset = round((sound.first_ns - mic.heard_at(0)) * RATE / 1e9)
    assert offset % 480 == 0 and offset > 0                    # it started mid-file, on a block
    assert np.array_equal(recorded, original[offset:offset + len(recorded)])
    assert take.meta["sound"]["mic"]["frames"] == len(recorded) == 480 * take.meta["samples"]
    assert abs(sound.first_ns - take.meta["t0_ns"]) < 50e6     # heard when recording began
    result = retake(take, tmp_path / "replay.fap", through_devices=True)
    assert result.identical and result.frames == take.meta["frames"]


def test_a_take_killed_mid_recording_keeps_its_sound_up_to_the_last_block(tmp_path):
    wav = speech(tmp_path, seconds=6.0)
    script = textwrap.dedent(f"""
        import os, signal, sys, time
        sys.path.insert(0, {str(ROOT)!r})
        from devices import open_device
        from puppet.io.shipped import shipped_mapping
        from puppet.live.session import LiveSession
        mic = open_device("wav://{wav}", "mic")
        session = LiveSession(shipped_mapping("voice"), devices={{"mic": mic}}, record_root={str(tmp_path)!r})
        session.normals = False
        session.start_recording()
        start = time.monotonic()
        while time.monotonic() - start < 1.5:
            session.wait_for_input(0.05)
            session.frame()
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False)
    assert run.returncode == -signal.SIGKILL, run.stderr
    [folder] = [p for p in tmp_path.iterdir() if p.is_dir()]
    take = open_take(folder)
    assert take.meta["complete"] is False and take.meta["sound"]["mic"]["frames"] == 0  # as written at its start
    info = soundfile.info(str(folder / "take.wav"))
    assert info.samplerate == RATE and 1.0 < info.duration < 2.0  # whole blocks, header true
    assert info.frames % 480 == 0
    pcm, _ = read_sound(folder / "take.wav")
    assert len(pcm) == info.frames and soundtrack(folder).seconds > 1.0
    result = retake(take, tmp_path / "replay.fap", through_devices=True)
    assert result.identical


def _click_take(tmp_path: Path) -> tuple[Path, float]:
    """A live take whose sound holds one click; returns it and where the click falls after the
    take's frame 0, in seconds, by the device's own clock."""
    sound = np.zeros(int(2.0 * RATE))
    click_at = 1.2371
    sound[int(click_at * RATE):int(click_at * RATE) + 24] = 0.9
    wav = write_wav(tmp_path / "click.wav", sound)
    folder, mic = record(tmp_path, wav, wait_s=0.25)
    t0 = open_take(folder).meta["t0_ns"]
    return folder, (mic.heard_at(int(click_at * RATE) / RATE) - t0) / 1e9


def _decoded(video: Path) -> tuple[np.ndarray, int]:
    import imageio_ffmpeg

    out = video.with_suffix(".decoded.wav")
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-i", str(video), "-vn",
                    "-acodec", "pcm_s16le", str(out)], check=True)
    return read_sound(out)


def test_a_click_recorded_in_a_take_lands_in_the_rendered_video_within_a_millisecond(tmp_path, egl):
    folder, expected = _click_take(tmp_path)
    video = tmp_path / "take.mp4"
    assert main(["render", str(folder), "-o", str(video), "--size", "160x120"]) == 0
    pcm, rate = _decoded(video)
    heard = int(np.argmax(np.abs(pcm.astype(float)))) / rate
    assert abs(heard - expected) < 0.001, (heard, expected)
    frames = len(read_fap(folder / "take.fap"))
    assert abs(len(pcm) / rate - frames / 30) < 0.03  # as long as the picture


def test_a_damaged_take_wav_renders_silent_with_a_warning_naming_it(tmp_path, egl, capsys):
    folder, _ = record(tmp_path, speech(tmp_path, seconds=0.8), wait_s=0.0)
    (folder / "take.wav").write_bytes(b"RIFF....WAVEjunk")
    video = tmp_path / "silent.mp4"
    assert main(["render", str(folder), "-o", str(video), "--size", "160x120"]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and str(folder / "take.wav") in err and "without sound" in err
    import imageio_ffmpeg

    probe = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-i", str(video)], capture_output=True, text=True,
                           check=False)  # ffmpeg with no output file exits 1 after describing its input
    assert "Video:" in probe.stderr and "Audio:" not in probe.stderr


def test_the_sound_out_follows_the_players_clock_and_says_when_there_is_no_output():
    pcm = np.arange(48000, dtype=np.int16)
    where = {"t": 0.0}
    out = ClockedSound(Soundtrack(pcm, 48000, Path("x.wav")), lambda now: where["t"])
    block = np.zeros(480, np.int16)
    out.fill(block, 0.0)
    assert np.array_equal(block, pcm[:480])
    where["t"] = 0.0103                               # the clock jitters a little: the stream goes on
    out.fill(block, 0.0)
    assert np.array_equal(block, pcm[480:960])
    where["t"] = 0.5                                  # a seek: it follows
    out.fill(block, 0.0)
    assert np.array_equal(block, pcm[24000:24480])
    where["t"] = None                                 # paused: silence
    out.fill(block, 0.0)
    assert not block.any()
    where["t"] = -0.005                               # before the sound starts: silence, then it
    out.fill(block, 0.0)
    assert not block[:240].any() and np.array_equal(block[240:], pcm[:240])
    notes = []
    if not out.start(notes.append):                   # this machine has no sound output
        assert len(notes) == 1 and notes[0].startswith("no sound output") and "\n" not in notes[0]
    out.close()


def test_lipsync_makes_a_take_that_renders_replays_and_exports_with_its_sound(tmp_path, egl, capsys):
    wav = speech(tmp_path)
    folder = tmp_path / "take"
    assert main(["lipsync", str(wav), "-o", str(folder)]) == 0
    assert "frames" in capsys.readouterr().out
    take = open_take(folder)
    assert take.meta["complete"] and (folder / "take.wav").is_file() and take.sounds()[0].first_ns == 0
    stream = read_fap(folder / "take.fap")
    assert abs(len(stream) - soundfile.info(str(wav)).duration * 30) <= 1
    jaw = stream.values[:, 2]
    assert jaw[0] == 0 and jaw[:24].max() > 150                     # silent, then the A opens the jaw
    assert retake(take, tmp_path / "replay.fap", through_devices=True).identical
    assert main(["render", str(folder), "-o", str(tmp_path / "v.mp4"), "--size", "160x120"]) == 0
    pcm, _ = _decoded(tmp_path / "v.mp4")
    assert np.abs(pcm).max() > 5000
    capsys.readouterr()
    assert main(["export", str(folder), "-o", str(tmp_path / "t.glb")]) == 0
    out, err = capsys.readouterr()
    assert [line.split(":")[0] for line in err.splitlines()] == ["export 1/3", "export 2/3", "export 3/3"]
    said = re.search(r"largest vertex error ([\d.e-]+) mm \(([\d.e-]+)% of the face's ([\d.]+) mm size\)", out)
    assert said and float(said[2]) == pytest.approx(100 * float(said[1]) / float(said[3]), rel=0.1)
    assert main(["lipsync", str(wav), "-o", str(folder)]) == 2        # never over a take


def test_lipsync_over_a_take_replaces_its_mouth_and_keeps_the_rest(tmp_path):
    folder = lipsync(demo_speech(), tmp_path / "over", over=demo_take(), fps=25)
    base, layered = held(demo_take()), held(folder / "take.fap")
    assert len(layered) == len(base)
    mouth = [f.number - 1 for f in faps() if f.group in MOUTH_GROUPS and f.number > 2]
    visemes = high_level_faps()["visemes"]
    shaped = {k for v in range(15) for k in np.flatnonzero(visemes[v])}  # the visemes move the cheeks too
    rest = [k for k in range(2, 68) if k not in mouth and k not in shaped]
    assert len(rest) > 25 and np.array_equal(layered[:, rest], base[:, rest])  # lids, eyes, head, brows
    assert not np.array_equal(layered[:, mouth], base[:, mouth])
    assert json.loads((folder / "take.json").read_text())["layer"]["over"] == str(demo_take().resolve())
    assert retake(open_take(folder), tmp_path / "replay.fap", through_devices=True).identical


def held(path: Path) -> np.ndarray:
    """A .fap's frames as a player holds them (untransmitted FAPs keep their last value)."""
    with iter_fap(path) as reader:
        return np.array([values.copy() for values in held_low_level(reader)])


def test_a_take_without_sound_has_no_soundtrack(tmp_path):
    assert soundtrack(demo_take()) is None
    with WavWriter(tmp_path / "x.wav", 8000) as writer:
        writer.write(np.ones(80, np.int16))
    assert soundtrack(tmp_path / "x.wav") is None


def test_a_slider_box_and_a_microphone_record_a_take_that_renders_with_the_voice(tmp_path, egl):
    """The performer's whole set-up: the sliders keep the brows and the blink, the voice the
    mouth; the take replays through both devices' wires and renders with the voice."""
    wav = speech(tmp_path, seconds=2.0)
    devices = {"box": open_device("sim://joystick?protocol=ascii&rate=200&channels=6", "box"),
               "mic": open_device(f"wav://{wav}", "mic")}
    with LiveSession(shipped_mapping("arduino_sliders_voice"), devices=devices, record_root=tmp_path) as session:
        session.normals = False
        session.start_recording()
        while not devices["mic"].finished:
            session.wait_for_input(0.05)
            session.frame()
        folder = session.stop_recording()
    take = open_take(folder)
    assert set(take.meta["devices"]) == {"box", "mic"} and [s.device for s in take.sounds()] == ["mic"]
    stream = held(folder / "take.fap")
    brows, jaw = stream[:, 30], stream[:, 2]
    assert np.ptp(brows) > 10 and jaw.max() > 100                       # the hands and the voice
    assert retake(take, tmp_path / "replay.fap", through_devices=True).identical
    assert main(["render", str(folder), "--size", "160x120"]) == 0
    pcm, _ = _decoded(folder / "take.mp4")
    assert np.abs(pcm).max() > 5000


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng is not installed (tools/setup.sh installs it)")
def test_lipsync_with_a_script_presses_the_lips_on_each_closure_and_replays_exactly(tmp_path):
    wav = tmp_path / "mama.wav"
    subprocess.run(["espeak-ng", "-v", "en-us", "-w", str(wav), "mama papa bobo"], check=True)
    folder = tmp_path / "scripted"
    assert main(["lipsync", str(wav), "-o", str(folder), "--script", "mama papa bobo"]) == 0
    take = open_take(folder)
    assert "script=mama+papa+bobo" in take.meta["devices"]["mic"]
    viseme = read_fap(folder / "take.fap").viseme[:, 0]  # FAP 1's select: the strongest viseme
    assert episodes(viseme == 1) >= 5             # p b m, pressed (30 frames/s may merge two)
    assert retake(take, tmp_path / "replay.fap", through_devices=True).identical
    assert main(["lipsync", str(wav), "-o", str(tmp_path / "x"), "--script", "hi", "--live"]) == 2


def test_every_audio_device_of_a_take_gets_its_own_wav(tmp_path):
    """Two microphones: the first in take.wav, the second in take.NAME.wav, each with its own
    rate and first sample's time in take.json; a device without sound writes none."""
    from devices.base import Sample, Sound
    from puppet.io.takes import TakeRecorder

    recorder = TakeRecorder(tmp_path, "duet", 30)
    for k in range(3):
        recorder.sample(Sample(1000 + k, "box", {"ch0": 1.0}))
        recorder.sample(Sample(2000 + k, "alto", {"level": 0.5}, Sound(np.full(480, k, np.int16), 48000, 500 + k)))
        recorder.sample(Sample(3000 + k, "tenor", {"level": 0.5}, Sound(np.full(441, -k, np.int16), 44100, 700 + k)))
    folder = recorder.close()
    sounds = {s.device: s for s in open_take(folder).sounds()}
    assert set(sounds) == {"alto", "tenor"}
    assert (sounds["alto"].path.name, sounds["alto"].rate, sounds["alto"].first_ns) == ("take.wav", 48000, 500)
    assert (sounds["tenor"].path.name, sounds["tenor"].rate, sounds["tenor"].first_ns) == ("take.tenor.wav", 44100, 700)
    tenor, rate = read_sound(sounds["tenor"].path)
    assert rate == 44100 and np.array_equal(tenor, np.repeat([0, -1, -2], 441).astype(np.int16))
    assert json.loads((folder / "take.json").read_text())["sound"]["alto"]["frames"] == 3 * 480
