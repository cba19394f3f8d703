"""The voice as a device: what the analysis hears in known sounds, wav:// at real-time pace, a
microphone that is not there, and sound files that are not what they claim."""

from __future__ import annotations

import shutil
import struct
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from devices import State, open_device
from devices.audio_device import discover
from devices.base import DeviceError
from devices.soundread import SoundFileError, read_sound
from devices.voice import CHANNELS, VOWELS, Voice
from devices.wav_device import WavDevice
from puppet.cli import main
from puppet.io.wavwriter import WavWriter

RATE = 48000
BLOCK = 480


def vowel(f1: float, f2: float, seconds: float = 0.4, pitch: float = 130.0, level: float = 0.25) -> np.ndarray:
    """A voiced vowel: a glottal pulse train's harmonics shaped by two formants."""
    t = np.arange(int(seconds * RATE)) / RATE
    wave = sum(np.sin(2 * np.pi * pitch * h * t) / h
               * sum(1.0 / (1.0 + ((pitch * h - f) / 90.0) ** 2) for f in (f1, f2)) for h in range(1, 60))
    return level * wave / np.abs(wave).max()


def hiss(seconds: float = 0.3, level: float = 0.2, seed: int = 0) -> np.ndarray:
    """An s: white noise above 4 kHz."""
    from scipy.signal import butter, sosfilt

    noise = np.random.default_rng(seed).standard_normal(int(seconds * RATE))
    high = sosfilt(butter(6, 4000, "highpass", fs=RATE, output="sos"), noise)
    return level * high / np.abs(high).max()


def write_wav(path: Path, sound: np.ndarray, rate: int = RATE) -> Path:
    with WavWriter(path, rate) as writer:
        writer.write(np.round(np.clip(sound, -1, 1) * 32767).astype(np.int16))
    return path


def readings(sound: np.ndarray) -> list[dict[str, float]]:
    pcm = np.round(sound * 32767).astype(np.int16)
    voice = Voice(RATE)
    return [voice(pcm[k:k + BLOCK]) for k in range(0, len(pcm) - BLOCK + 1, BLOCK)]


def settled(sound: np.ndarray) -> dict[str, float]:
    """The readings' means over the sound's second half (the analysis settled)."""
    rows = readings(sound)[len(readings(sound)) // 2:]
    return {name: float(np.mean([r[name] for r in rows])) for name in CHANNELS}


@pytest.mark.parametrize(("name", "f1", "f2"), [("aa", 750, 1200), ("i", 280, 2350), ("u", 300, 750)])
def test_a_vowel_picks_its_viseme_channel_and_opens_the_mouth_as_wide_as_it_is_open(name, f1, f2):
    heard = settled(vowel(f1, f2))
    vowels = {v: heard[v] for v in VOWELS}
    assert max(vowels, key=vowels.get) == name
    assert heard["gate"] == 1 and heard["voiced"] > 0.8 and heard["level"] > 0.5
    assert 130 / 1.1 < 70 * (400 / 70) ** heard["pitch"] < 130 * 1.1  # the held pitch, 130 Hz
    if name == "aa":
        assert heard["open"] > settled(vowel(280, 2350))["open"] + 0.2
    if name == "i":
        assert heard["wide"] > heard["round"]
    if name == "u":
        assert heard["round"] > heard["wide"]


def test_silence_closes_everything_and_hiss_is_an_s():
    quiet = settled(np.zeros(RATE // 2))
    assert quiet["db"] == -120 and all(quiet[c] == 0 for c in CHANNELS if c != "db")
    s = settled(hiss())
    assert s["ss"] > 0.3 and s["voiced"] < 0.3 and s["aa"] < 0.05
    faint = settled(hiss(level=0.04))
    assert faint["ff"] > faint["ss"] and faint["ff"] > 0.05


def test_a_stop_inside_speech_presses_the_lips_and_a_pause_does_not_keep_them_pressed():
    sound = np.concatenate([vowel(750, 1200), np.zeros(int(0.06 * RATE)), vowel(750, 1200), np.zeros(RATE)])
    rows = readings(sound)
    stop = rows[int(0.4 / 0.01) + 4]
    assert stop["closed"] > 0.5 and stop["open"] < rows[30]["open"]
    assert rows[-1]["closed"] < 0.05  # a second after speech the lips rest apart


def test_the_noise_gate_holds_noise_below_it_shut_and_the_option_moves_it():
    noise = 0.003 * np.random.default_rng(1).standard_normal(RATE // 2)  # about -50 dBFS
    pcm = np.round(noise * 32767).astype(np.int16)
    for gate, opened in ((-45.0, False), (-60.0, True)):
        voice = Voice(RATE, gate)
        rows = [voice(pcm[k:k + BLOCK]) for k in range(0, len(pcm) - BLOCK + 1, BLOCK)]
        assert (rows[-1]["gate"] == 1) is opened
        assert (rows[-1]["level"] > 0) is opened


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([0, 1, 100, 3000, 32767]), st.integers(3, 8), st.integers(1, 2))
def test_any_sound_gives_readings_in_range_and_a_restored_state_continues_bit_for_bit(seed, loudness, blocks, split):
    rng = np.random.default_rng(seed)
    pcm = np.clip(rng.standard_normal(BLOCK * blocks) * loudness, -32768, 32767).astype(np.int16)
    blocks = [pcm[k:k + BLOCK] for k in range(0, len(pcm) - BLOCK + 1, BLOCK)]
    whole = Voice(RATE)
    rows = [whole(b) for b in blocks]
    for row in rows:
        assert set(row) == set(CHANNELS) and -120 <= row["db"] <= 0
        assert all(0.0 <= row[c] <= 1.0 for c in CHANNELS if c != "db")
    first = Voice(RATE)
    for block in blocks[:split]:
        first(block)
    again = Voice(RATE)
    again.restore(first.state())
    assert [again(b) for b in blocks[split:]] == rows[split:]


def test_wav_plays_at_real_time_pace_block_by_block_with_its_sound(tmp_path):
    wav = write_wav(tmp_path / "a.wav", vowel(750, 1200, seconds=0.6))
    device = open_device(f"wav://{wav}", "mic")
    start = time.monotonic()
    samples = []
    with device:
        while not device.finished and time.monotonic() - start < 5:
            samples += device.drain()
            time.sleep(0.01)
        samples += device.drain()
    assert 0.55 < time.monotonic() - start < 2.0
    assert len(samples) == 60 and device.counters.overruns == 0
    starts = np.array([s.sound.start_ns for s in samples])
    assert np.all(np.diff(starts) == pytest.approx(10_000_000, abs=1))  # the schedule, not the reader's
    assert all(s.t_ns >= s.sound.start_ns + 10_000_000 for s in samples)  # read once the block was heard
    assert np.array_equal(np.concatenate([s.sound.pcm for s in samples]), read_sound(wav)[0][:60 * BLOCK])
    assert set(samples[30].values) == set(CHANNELS) and samples[30].values["aa"] > 0.3


def test_wav_reads_other_formats_and_rates_resampled(tmp_path):
    import soundfile

    sound = vowel(750, 1200, seconds=0.3)
    flac = tmp_path / "a.flac"
    soundfile.write(flac, np.stack([sound, sound], axis=1)[::3], 16000)  # stereo FLAC at 16 kHz
    pcm, rate = read_sound(flac, RATE)
    assert rate == RATE and abs(len(pcm) - len(sound)) <= 3
    device = WavDevice("mic", flac, speed=0)
    device.load()
    heard = [values for _, values in device.readings()]
    assert len(heard) == len(pcm) // BLOCK and max(r["level"] for r in heard) > 0.5


def test_options_are_checked_where_the_url_is_given(tmp_path):
    for url, words in (("wav://x.wav?block=1s", "block='1s'"), ("wav://x.wav?rate=4000", "rate=4000"),
                       ("wav://x.wav?gate=5", "gate=5"), ("wav://x.wav?speed=fast", "speed"),
                       ("wav://x.wav?loud=1", "unknown option 'loud'"), ("audio://?block=abc", "block")):
        with pytest.raises(DeviceError, match=words):
            open_device(url, "mic")
    assert open_device("wav://x.wav?block=480&rate=44100", "mic").block == 480


def test_a_missing_microphone_is_lost_with_the_reason_and_listing_inputs_works():
    """Through the real PortAudio: an input no machine has is LOST with the reason; and a machine
    with no input at all (sounddevice's interface, no microphone plugged) says so."""
    from devices.audio_device import AudioDevice
    from devices.base import Url
    from devices.simulated_audio import FakeSoundDevice

    named = open_device("audio://NoSuchMicrophone%20XYZ", "mic").start()
    bare = AudioDevice.from_url(Url.parse("audio://"), "mic2", sd_module=FakeSoundDevice()).start()
    try:
        assert named.wait_state(State.LOST, 5) and "NoSuchMicrophone XYZ" in named.counters.last_error
        assert bare.wait_state(State.LOST, 5)
        assert bare.counters.last_error == "not plugged in: no sound input on this machine (no default input device)"
    finally:
        named.close()
        bare.close()
    assert all(found.url.startswith("audio://") for found in discover())


BAD = {
    "empty.wav": b"",
    "header.wav": b"RIFX" + b"\x00" * 40 + b"not a sound at all" * 10,
    "text.wav": b"hello, this is not a WAV file\n" * 20,
}


def _claiming(path: Path, frames: int, actual: int) -> Path:
    """A WAV whose header claims ``frames`` 16-bit frames but holds ``actual``."""
    data = 2 * frames
    header = (b"RIFF" + struct.pack("<I", 36 + data) + b"WAVE" + b"fmt " + struct.pack("<IHHIIHH", 16, 1, 1, RATE,
              2 * RATE, 2, 16) + b"data" + struct.pack("<I", data))
    path.write_bytes(header + b"\x01\x00" * actual)
    return path


@pytest.mark.parametrize("kind", [*BAD, "truncated", "gigabyte"])
def test_a_bad_sound_file_is_one_clear_line_everywhere_it_is_read(tmp_path, kind, capsys):
    if kind == "truncated":
        path = _claiming(tmp_path / "truncated.wav", RATE, RATE // 3)
    elif kind == "gigabyte":
        path = _claiming(tmp_path / "gigabyte.wav", (1 << 30) // 2, 100)
    else:
        path = tmp_path / kind
        path.write_bytes(BAD[kind])
    with pytest.raises(SoundFileError) as error:
        read_sound(path)
    message = str(error.value)
    assert str(path) in message and "\n" not in message
    device = open_device(f"wav://{path}", "mic").start()
    try:
        assert device.wait_state(State.LOST, 5) and str(path) in device.counters.last_error
    finally:
        device.close()
    assert main(["lipsync", str(path), "-o", str(tmp_path / "take")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("puppet lipsync: ") and str(path) in err[0]
    assert not (tmp_path / "take").exists() or not any((tmp_path / "take").iterdir())


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng is not installed (tools/setup.sh installs it)")
def test_espeak_vowels_are_heard_as_their_visemes(tmp_path):
    """Synthetic speech with known phonemes: a held "ah" is A, a held "ee" is I, a held "oo" is
    rounded, and the spoken sentence opens the mouth while it is spoken and not before."""
    heard = {}
    for word, text in (("ah", "[[A:::::::]]"), ("ee", "[[i:::::::]]"), ("oo", "[[u:::::::]]")):
        path = tmp_path / f"{word}.wav"
        subprocess.run(["espeak-ng", "-v", "en-us", "-w", str(path), text], check=True)
        pcm, _ = read_sound(path, RATE)
        heard[word] = settled(pcm.astype(np.float64) / 32768)
    assert max(VOWELS, key=lambda v: heard["ah"][v]) == "aa"
    assert heard["ee"]["wide"] > heard["ee"]["round"] and heard["ee"]["i"] > heard["ee"]["aa"]
    assert heard["oo"]["round"] > heard["oo"]["wide"] and heard["oo"]["u"] + heard["oo"]["o"] > heard["oo"]["aa"]
    assert heard["ah"]["open"] > heard["ee"]["open"]


@settings(max_examples=150, deadline=None)
@given(st.sampled_from([b"", b"RIFF\x24\x00\x00\x00WAVEfmt ", b"RIFF\xff\xff\xff\x7fWAVE", b"fLaC", b"OggS"]),
       st.binary(max_size=600))
def test_garbage_in_a_sound_file_is_read_or_refused_with_a_sound_file_error(tmp_path_factory, head, tail):
    path = tmp_path_factory.mktemp("fuzz") / "garbage.wav"
    path.write_bytes(head + tail)
    try:
        pcm, rate = read_sound(path, RATE)
    except SoundFileError as error:
        assert str(path) in str(error) and "\n" not in str(error)
    else:
        assert pcm.dtype == np.int16 and rate == RATE and len(pcm) > 0


def episodes(flags: np.ndarray) -> int:
    """How many runs of True a sequence holds."""
    return int(np.sum(np.diff(np.concatenate([[0], flags.astype(int)])) == 1))


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng is not installed (tools/setup.sh installs it)")
def test_a_script_puts_each_closure_and_vowel_where_the_voice_says_it(tmp_path):
    """"mama papa bobo" has six lip closures: the sound alone hears an m as a hum, so its
    closures blur; aligned to its script, each one is there, in order, with the right vowel
    between them, and nothing is pressed before the speech starts."""
    from devices.voice import offline
    from devices.voicescript import script_phones

    path = tmp_path / "mama.wav"
    subprocess.run(["espeak-ng", "-v", "en-us", "-w", str(path), "mama papa bobo"], check=True)
    pcm, _ = read_sound(path, RATE)
    blocks = [pcm[k:k + BLOCK] for k in range(0, len(pcm) - BLOCK + 1, BLOCK)]
    words = script_phones("mama papa bobo")
    assert words == [["closed", "aa", "closed", "aa"], ["closed", "aa", "closed", "e"],
                     ["closed", "o", "closed", "o"]]
    rows = offline(blocks, RATE, script=words)
    closed = np.array([r["closed"] for r in rows]) > 0.5
    assert episodes(closed) == 6
    first = int(np.argmax(closed))
    assert all(r["closed"] < 0.05 for r in rows[:max(0, first - 10)])
    vowel_order = [max(("aa", "e", "o"), key=lambda v: r[v]) for r in rows if r["level"] > 0.3 and r["closed"] < 0.2]
    assert vowel_order.index("o") > vowel_order.index("aa")          # bobo after mama and papa
    assert sum(v == "o" for v in vowel_order[-10:]) >= 5
    unaided = np.array([r["closed"] for r in offline(blocks, RATE)]) > 0.5
    assert episodes(unaided) < 6


def test_a_script_needs_the_offline_analysis_and_espeak_reads_it(tmp_path):
    with pytest.raises(DeviceError, match="mode=offline"):
        open_device("wav://x.wav?script=hello", "mic")
    from devices.voicescript import shape_of

    assert [shape_of(p) for p in ("p", "'A:", "i:", "'oU", "u:", "s", "v", "t", "w")] == [
        "closed", "aa", "i", "o", "u", "ss", "ff", "other", "u"]


def test_puppet_devices_lists_each_sound_input_as_a_url_that_opens_it():
    from devices.audio_device import AudioDevice
    from devices.base import Url
    from devices.simulated_audio import FakeMicrophone, FakeSoundDevice

    module = FakeSoundDevice(FakeMicrophone("USB Headset Mic: Audio (hw:2,0)", np.zeros(4800, np.int16)))
    [found] = discover(module)
    assert found.url == "audio://USB%20Headset%20Mic%3A%20Audio%20%28hw%3A2%2C0%29"
    assert "input 0" in found.description and "48000 Hz" in found.description
    device = AudioDevice.from_url(Url.parse(found.url), "mic", sd_module=module).start()
    try:
        assert device.wait_state(State.OPEN, 3) and next(device.samples(timeout=2)).sound.rate == RATE
    finally:
        device.close()
