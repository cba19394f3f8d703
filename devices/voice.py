"""What a voice says to a face: a causal analysis of sound blocks into mouth channels.

Every audio device (``audio://`` on a sound card, ``wav://`` from a file) runs one ``Voice`` over
its blocks (10 ms by default) in its reader thread, off the live loop. Each block becomes one
reading with these channels, each 0..1 unless said otherwise:

``db``
    the block's level in dBFS (-120..0), unsmoothed: what the cockpit's meter shows.
``gate``
    1 while the noise gate is open (the level rose above ``gate`` dBFS; it closes 6 dB lower
    after ``HOLD_S`` of quiet), else 0.
``level``
    loudness above the gate over ``SPAN_DB`` (0 when the gate is shut): "mouth open = loud".
``voiced``
    how periodic the sound is (the normalised autocorrelation's peak between 70 and 400 Hz, over
    the last 2.5 periods of a 70 Hz voice).
``pitch``
    that peak's frequency on a log scale from 70 Hz (0) to 400 Hz (1), held through unvoiced sound.
``open``
    the lips' vertical opening: loudness, raised by the first formant (F1 rises as the jaw
    drops), compressed (a square root: a quiet syllable opens the mouth more than its share of
    loudness) and narrowed by rounding (an oo's lips are close together, however loud).
``wide`` / ``round``
    lips spread (a high second formant: /i/, /e/) or rounded (a low one: /o/, /u/).
``closed``
    lips pressed: the sound dropped out inside speech (a stop such as p, b, m), for up to
    ``CLOSURE_S`` after the last loud block; after that the lips part again to rest. Offline,
    only a drop that speech follows within ``CLOSURE_S`` is a closure (a pause is not).
``aa`` ``e`` ``i`` ``o`` ``u``
    the five vowels' shares of the voiced loudness, by the nearest formant pattern (MPEG-4
    visemes 10, 11, 12, 13 and 14).
``ss`` / ``ff``
    hiss: a loud unvoiced sound with most energy above 3.5 kHz (s, z: viseme 7), or a weak one
    (f, v: viseme 2).

The formants come from the cepstrally smoothed spectrum of the last ``WINDOW_S`` of sound (a Hann
window of the next power of two), as band-weighted peaks: no model, no language. Mouth channels
rise with a time constant of ``ATTACK_S`` and fall with ``RELEASE_S``. The analysis is a pure
function of the blocks it was given and its ``state()``: the same blocks give the same readings,
bit for bit, which is what lets a take's sound be replayed through ``wav://`` into the same
frames. ``offline`` analyses a whole recording with look-ahead for ``puppet lipsync``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from devices.voicescript import scripted

CHANNELS = ("db", "gate", "level", "voiced", "pitch", "open", "wide", "round", "closed",
            "aa", "e", "i", "o", "u", "ss", "ff")
VOWELS = {"aa": (0.85, 0.35), "e": (0.45, 0.75), "i": (0.10, 0.95), "o": (0.50, 0.10), "u": (0.10, 0.05)}
"""Each vowel's (F1, F2) on the scales of ``_formants``: F1 300-800 Hz, F2 1000-2400 Hz -> 0..1."""
VOWEL_SPREAD = 0.08
SMOOTHED = ("level", "open", "wide", "round", "closed", "aa", "e", "i", "o", "u", "ss", "ff")

GATE_DB = -45.0       # dBFS where the gate opens
GATE_HYSTERESIS = 6.0
SPAN_DB = 36.0        # dB above the gate that make full loudness
HOLD_S = 0.25         # seconds the gate stays open in quiet
CLOSURE_S = 0.12      # the longest drop in the sound taken as lips pressed (a stop's closure)
WINDOW_S = 0.02       # seconds of sound each spectrum looks at (rounded up to a power of two)
ATTACK_S = 0.012
RELEASE_S = 0.045
PITCH_RANGE = (70.0, 400.0)
PITCH_PERIODS = 2.5   # the longest period's count in the window that finds the pitch
LIFTER_S = 0.0015     # quefrency kept in the spectral envelope: below a 400 Hz voice's period
HISS_HZ = 3500.0


class Voice:
    """The causal analysis of one voice (see the module docstring): ``voice(pcm)`` takes the next
    block of 16-bit mono PCM and returns its reading."""

    def __init__(self, rate: int, gate_db: float = GATE_DB) -> None:
        if not 8000 <= rate <= 192000:
            raise ValueError(f"rate={rate}: expected 8000 to 192000 Hz")
        if not -120.0 <= gate_db <= 0.0:
            raise ValueError(f"gate={gate_db:g}: expected a level from -120 to 0 dBFS")
        self.rate, self.gate_db = int(rate), float(gate_db)
        self.n = 1 << max(8, math.ceil(math.log2(WINDOW_S * rate)))
        self.n_pitch = 1 << math.ceil(math.log2(PITCH_PERIODS / PITCH_RANGE[0] * rate))
        self._window = np.hanning(self.n).astype(np.float64)
        self._pitch_window = np.hanning(self.n_pitch).astype(np.float64)
        self._freqs = np.fft.rfftfreq(self.n, 1.0 / rate)
        self._f1 = (self._freqs >= 250) & (self._freqs <= 1000)
        self._f2 = (self._freqs >= 900) & (self._freqs <= 3000)
        self._speech = self._freqs >= 100
        self._hiss = self._freqs >= HISS_HZ
        ac = np.fft.irfft(np.abs(np.fft.rfft(self._pitch_window, 2 * self.n_pitch)) ** 2)[: self.n_pitch]
        self._window_ac = ac / ac[0]  # the window's own autocorrelation, to undo
        self._lags = slice(int(rate / PITCH_RANGE[1]), int(rate / PITCH_RANGE[0]) + 1)
        self._lifter = max(4, int(LIFTER_S * rate))
        self.reset()

    def reset(self) -> None:
        """Back to silence: an empty window, the gate shut, every channel 0."""
        self._ring = np.zeros(self.n_pitch, dtype=np.int16)
        self._quiet_s = HOLD_S      # seconds since the level was last above the gate
        self._gate = False
        self._pitch = 0.0
        self._out = dict.fromkeys(CHANNELS, 0.0)
        self._out["db"] = -120.0

    # -- state, for a take to replay the analysis exactly ---------------------------------------

    def state(self) -> dict[str, Any]:
        """Everything the next reading depends on besides the next block (JSON-able once the
        window, ``ring``, is a list: ``json_state``)."""
        return {"ring": self._ring.copy(), "quiet_s": self._quiet_s, "gate": self._gate,
                "pitch": self._pitch, "out": dict(self._out)}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()``; a ValueError names what does not fit this analysis."""
        ring = np.asarray(state["ring"], dtype=np.int64)
        if ring.shape != (self.n_pitch,) or np.any((ring < -32768) | (ring > 32767)):
            raise ValueError(f"a voice state's window holds {ring.shape} samples, expected {self.n_pitch} 16-bit ones")
        out = {name: float(state["out"][name]) for name in CHANNELS}
        self._ring = ring.astype(np.int16)
        self._quiet_s, self._gate = float(state["quiet_s"]), bool(state["gate"])
        self._pitch, self._out = float(state["pitch"]), out

    # -- the analysis -----------------------------------------------------------------------

    def __call__(self, pcm: np.ndarray) -> dict[str, float]:
        """The reading of the next block (16-bit mono PCM at ``rate``): the channels above."""
        pcm = np.asarray(pcm, dtype=np.int16).reshape(-1)
        dt = len(pcm) / self.rate
        self._ring = np.concatenate([self._ring, pcm])[-self.n_pitch:]
        x = pcm.astype(np.float64) / 32768.0
        db = max(-120.0, 10.0 * math.log10(float(np.mean(x * x)) + 1e-12)) if len(x) else -120.0
        self._update_gate(db, dt)
        target = self._targets(db)
        out = self._out
        for name in SMOOTHED:
            tau = ATTACK_S if target[name] > out[name] else RELEASE_S
            out[name] += (1.0 - math.exp(-dt / tau)) * (target[name] - out[name])
        out["db"], out["gate"] = db, float(self._gate)
        out["voiced"], out["pitch"] = target["voiced"], self._pitch
        return dict(out)

    def _update_gate(self, db: float, dt: float) -> None:
        if db > self.gate_db:
            self._gate, self._quiet_s = True, 0.0
            return
        self._quiet_s += dt
        if db < self.gate_db - GATE_HYSTERESIS and self._quiet_s >= HOLD_S:
            self._gate = False

    def _targets(self, db: float) -> dict[str, float]:
        """What each channel heads for in this block, before the attack and release."""
        level = _unit((db - self.gate_db) / SPAN_DB) if self._gate else 0.0
        ring = self._ring.astype(np.float64) / 32768.0
        power = np.abs(np.fft.rfft(ring[-self.n:] * self._window)) ** 2 + 1e-18
        voiced = self._voicing(ring)
        f1, f2 = self._formants(power)
        speaking = voiced * level
        weights = {v: math.exp(-((f1 - a) ** 2 + (f2 - b) ** 2) / VOWEL_SPREAD) for v, (a, b) in VOWELS.items()}
        total = sum(weights.values()) or 1.0
        hiss_share = float(power[self._hiss].sum() / power[self._speech].sum())
        hiss = level * (1.0 - voiced) * _unit((hiss_share - 0.3) / 0.4)
        strong = _unit((db - self.gate_db - 12.0) / 12.0)
        pressed = 1.0 if (self._gate and level < 0.08 and self._quiet_s < CLOSURE_S) else 0.0
        rounded = speaking * (1.0 - f2) * (1.0 - f1)
        target = {"level": level, "voiced": voiced,
                  "open": max(0.0, math.sqrt(level * (0.3 + 0.7 * f1 * voiced)) - rounded),
                  "wide": speaking * f2 * (1.0 - 0.5 * f1),
                  "round": rounded,
                  "closed": pressed, "ss": hiss * strong, "ff": hiss * (1.0 - strong)}
        target.update({v: speaking * w / total for v, w in weights.items()})
        return target

    def _voicing(self, ring: np.ndarray) -> float:
        """How periodic the last ``n_pitch`` samples are (0..1); voiced, they set the held pitch."""
        power = np.abs(np.fft.rfft(ring * self._pitch_window, 2 * self.n_pitch)) ** 2
        ac = np.fft.irfft(power)[: self.n_pitch] / self._window_ac
        if ac[0] <= 0:
            return 0.0
        lags = ac[self._lags] / ac[0]
        peak = float(lags.max())
        best = int(np.argmax(lags >= 0.85 * peak))  # the shortest period near the highest peak:
        while best + 1 < len(lags) and lags[best + 1] > lags[best]:  # not a multiple of it
            best += 1
        if peak > 0.45:
            hz = self.rate / (self._lags.start + best)
            low, high = PITCH_RANGE
            self._pitch = _unit(math.log(hz / low) / math.log(high / low))
        return _unit((peak - 0.3) / 0.5)

    def _formants(self, power: np.ndarray) -> tuple[float, float]:
        """F1 and F2 of the cepstrally smoothed spectrum, each on a 0..1 scale."""
        cepstrum = np.fft.irfft(np.log(power))
        cepstrum[self._lifter:-self._lifter] = 0.0
        envelope = np.exp(np.fft.rfft(cepstrum).real)
        f1 = _peak(self._freqs[self._f1], envelope[self._f1])
        above = self._f2 & (self._freqs > f1 + 250)
        f2 = _peak(self._freqs[above], envelope[above])
        return _unit((f1 - 300.0) / 500.0), _unit((f2 - 1000.0) / 1400.0)


def json_state(state: Mapping[str, Any]) -> dict[str, Any]:
    """A ``Voice.state()`` (or any analysis state with arrays in it) as JSON can hold it."""
    return {key: value.tolist() if isinstance(value, np.ndarray) else value for key, value in state.items()}


def _unit(x: float) -> float:
    """``x`` held within 0..1."""
    return min(1.0, max(0.0, x))


def _peak(freqs: np.ndarray, envelope: np.ndarray) -> float:
    """A band's formant: the envelope's centre of mass, sharpened toward its peak."""
    if len(freqs) == 0:
        return 0.0
    weights = (envelope / envelope.max()) ** 4
    return float((freqs * weights).sum() / weights.sum())


LOOKAHEAD_S = 0.06    # how far ahead of its sound ``offline`` moves the lips
OFFLINE_SMOOTH_S = 0.03


def offline(blocks: list[np.ndarray], rate: int, gate_db: float = GATE_DB,
            script: list[list[str]] | None = None) -> list[dict[str, float]]:
    """Readings for a whole recording, one per block, with look-ahead: each channel as ``Voice``
    gives it (or, given the ``script``'s words as mouth shapes, as ``devices.voicescript`` aligns
    them), then smoothed forwards and backwards (no lag) and, for the lips, led by
    ``LOOKAHEAD_S`` (lips close before a p and open before a vowel is heard)."""
    voice = Voice(rate, gate_db)
    rows = [voice(block) for block in blocks]
    if not rows:
        return []
    if script is not None:
        rows = scripted(rows, script)
    dt = len(blocks[0]) / rate
    lead = round(LOOKAHEAD_S / dt)
    table = {name: np.array([row[name] for row in rows]) for name in CHANNELS}
    if script is None:
        table["closed"] = _closures(table["level"], dt)
    for name in SMOOTHED:
        crisp = script is not None and name == "closed"  # an aligned closure: the lips meet, then part
        values = table[name] if crisp else _zero_phase(table[name], dt)
        table[name] = np.concatenate([values[lead:], np.full(min(lead, len(values)), values[-1])])
    return [{name: float(table[name][k]) for name in CHANNELS} for k in range(len(rows))]


def _closures(level: np.ndarray, dt: float) -> np.ndarray:
    """1 over every drop of the sound inside speech shorter than ``CLOSURE_S``, else 0."""
    quiet = level < 0.08
    out = np.zeros(len(level))
    k = 0
    while k < len(quiet):
        if not quiet[k]:
            k += 1
            continue
        end = k
        while end < len(quiet) and quiet[end]:
            end += 1
        if 0 < k and end < len(quiet) and (end - k) * dt <= CLOSURE_S:
            out[k:end] = 1.0
        k = end
    return out


def _zero_phase(values: np.ndarray, dt: float) -> np.ndarray:
    """A one-pole smoother of ``OFFLINE_SMOOTH_S`` run forwards, then backwards: no lag."""
    from scipy.signal import filtfilt

    if len(values) < 4:
        return values.astype(np.float64)
    a = 1.0 - math.exp(-dt / OFFLINE_SMOOTH_S)
    smooth: np.ndarray = filtfilt([a], [1.0, a - 1.0], values.astype(np.float64), padlen=min(len(values) - 1, 30))
    return smooth
