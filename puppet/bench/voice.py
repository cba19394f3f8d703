"""The voice in the live loop, for ``puppet bench --only voice``: sync, the analysis's cost, and
what a microphone open costs the frame rate.

* ``sound_to_drawn_ms``: a ``wav://`` device plays ``BURSTS`` vowel-like bursts (a 140 Hz voice
  through two formants, -14 dBFS) with silence between, at real-time pace, into a live session
  on ``voice.yaml``; every frame is drawn and read back offscreen at 640x480. For each burst: from
  the moment its first sample is heard (the device's clock) to the first frame drawn whose lips
  have parted by a tenth of that burst's widest gap. Median and 99th percentile.
* ``analysis_ms_per_block``: the CPU time of ``devices.voice.Voice`` on one 10 ms block of 48 kHz
  speech (median over the bursts' blocks).
* ``fps_without_mic`` / ``fps_with_mic``: the slider box's live loop drawing as fast as it can,
  without and with a microphone open beside it (its analysis in its reader thread), in turns in
  the same run (medians of three runs each); ``fps_ratio`` is with over without.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from devices.soundread import read_sound
from devices.voice import Voice
from devices.wav_device import WavDevice
from puppet.bench.pipeline import live_box, live_renderer
from puppet.bench.voicetruth import inner_lip_gap
from puppet.io.shipped import shipped_mapping
from puppet.io.wavwriter import WavWriter
from puppet.live.session import LiveSession
from puppet.runtime.runtime import Runtime

RATE = 48000
BURSTS = 30
ROUNDS = 3
BURST_S, GAP_S = 0.3, 0.45
SHOWN = 0.1   # the share of a burst's widest gap that makes it "shown"


def bursts(path: Path) -> list[float]:
    """Write the bursts' WAV to ``path``; return each burst's onset in seconds."""
    t = np.arange(int(BURST_S * RATE)) / RATE
    voice = sum(np.sin(2 * np.pi * 140 * h * t) / h * _formants(140 * h) for h in range(1, 30))
    burst = 0.2 * voice / np.abs(voice).max() * np.minimum(1.0, t / 0.005)
    gap = np.zeros(int(GAP_S * RATE))
    onsets, parts = [], [np.zeros(RATE)]
    for _ in range(BURSTS):
        onsets.append(sum(len(p) for p in parts) / RATE)
        parts += [burst, gap]
    with WavWriter(path, RATE) as writer:
        writer.write(np.round(np.concatenate(parts) * 32767).astype(np.int16))
    return onsets


def _formants(hz: float) -> float:
    """An open vowel's resonances (F1 700 Hz, F2 1200 Hz) at ``hz``."""
    return sum(1.0 / (1.0 + ((hz - f) / 120.0) ** 2) for f in (700.0, 1200.0)) + 0.05


def voice(runtime: Runtime, size: tuple[int, int] = (640, 480), fps_seconds: float = 9.0) -> dict:
    """The figures of the module docstring."""
    with tempfile.TemporaryDirectory(prefix="facepuppet-voice-") as folder:
        wav = Path(folder) / "bursts.wav"
        onsets = bursts(wav)
        lags = _sound_to_drawn(runtime, wav, onsets, size)
        cost = _analysis_ms(wav)
        without, with_mic = _fps_pair(runtime, wav, size, fps_seconds)
    return {"sound_to_drawn_ms": {"median": statistics.median(lags), "p99": float(np.percentile(lags, 99)),
                                  "bursts": len(lags)},
            "analysis_ms_per_block": cost, "fps_without_mic": without, "fps_with_mic": with_mic,
            "fps_ratio": with_mic / without}


def _sound_to_drawn(runtime: Runtime, wav: Path, onsets: list[float], size: tuple[int, int]) -> list[float]:
    face = runtime.face
    mic = WavDevice("mic", wav)
    drawn: list[tuple[int, float]] = []
    with LiveSession(shipped_mapping("voice"), face=runtime, devices={"mic": mic}) as session:
        renderer = live_renderer(runtime, size)
        try:
            session.normals = not renderer.gpu_normals
            renderer.render(runtime.rest, runtime.rest_normals)  # warm-up: shaders, buffers
            while not mic.finished:
                session.wait_for_input(0.05)
                frame = session.frame()
                renderer.render(frame.vertices, frame.normals)
                drawn.append((time.monotonic_ns(), inner_lip_gap(face, frame.vertices)))
        finally:
            renderer.release()
    times = np.array([t for t, _ in drawn])
    gaps = np.array([g for _, g in drawn])
    rest = inner_lip_gap(face, runtime.rest)
    lags = []
    for onset in onsets:
        start = mic.heard_at(onset)
        inside = (times >= start) & (times <= start + int((BURST_S + 0.1) * 1e9))
        threshold = rest + SHOWN * (gaps[inside].max() - rest)
        shown = np.flatnonzero(inside & (gaps >= threshold))
        if len(shown):
            lags.append((times[shown[0]] - start) / 1e6)
    return lags


def _analysis_ms(wav: Path) -> float:
    pcm, _ = read_sound(wav, RATE)
    block = RATE // 100
    voice = Voice(RATE)
    costs = []
    for k in range(0, len(pcm) - block + 1, block):
        start = time.process_time_ns()
        voice(pcm[k:k + block])
        costs.append((time.process_time_ns() - start) / 1e6)
    return statistics.median(costs)


def _fps_pair(runtime: Runtime, wav: Path, size: tuple[int, int], seconds: float) -> tuple[float, float]:
    """The slider box's loop rate, drawing as fast as it can, without and with a microphone open:
    the median of ``ROUNDS`` runs of each, taken in turns (the machine's pace drifts)."""
    rates: dict[bool, list[float]] = {False: [], True: []}
    for _ in range(ROUNDS):
        for mic in (False, True):
            extra = {"mic": f"wav://{wav}?loop=1"} if mic else None
            with live_box(runtime, size, extra=extra) as (session, renderer):
                frames, start = 0, time.perf_counter()
                while time.perf_counter() - start < seconds / ROUNDS:
                    frame = session.frame()
                    renderer.render(frame.vertices, frame.normals)
                    frames += 1
                rates[mic].append(frames / (time.perf_counter() - start))
    return statistics.median(rates[False]), statistics.median(rates[True])


__all__ = ["bursts", "voice"]
