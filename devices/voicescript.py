"""The words a recording says, aligned to it: a script's phones put where the voice says them.

``puppet lipsync --script "the words"`` knows what is said, not when. espeak-ng (apt) turns the
script into its phones (``espeak-ng -q -x --sep=' '``: ASCII phoneme names, words apart), each
phone becomes the mouth shape it needs (``PHONE_SHAPES``: a vowel's viseme, lips pressed for p b
m, hiss for s z sh ch, f v, or "other" for the consonants the jaw and tongue make), and a Viterbi
pass lays them over the recording's blocks in order: each phone at least ``SHORTEST`` blocks
(a closure ``MIN_BLOCKS``),
silence allowed between words, every block scored by how well the voice's own readings fit the
shape (``devices.voice``: vowel shares, loudness, hiss). What the audio cannot tell apart (an m
from a pause, an oo from an oh) the script now says; when the voice says it stays the audio's.
No model: it works for every language espeak-ng speaks (``language``, default ``en-us``).
"""

from __future__ import annotations

import math
import shutil
import subprocess
from collections.abc import Mapping, Sequence

import numpy as np

from devices.base import DeviceError

VOWELS = ("aa", "e", "i", "o", "u")
SHAPES = (*VOWELS, "closed", "ss", "ff", "other", "silence")
MIN_BLOCKS = {"closed": 5}  # 50 ms: a stop's closure is the shortest it holds
SHORTEST = 3                # 30 ms: any other phone
FLOOR = 1e-3            # the least probability a block gives any shape
PHONE_SHAPES = {
    "p": "closed", "b": "closed", "m": "closed",
    "f": "ff", "v": "ff",
    "s": "ss", "z": "ss", "S": "ss", "Z": "ss", "tS": "ss", "dZ": "ss",
    "w": "u",
}
VOWEL_STARTS = (("aI", "aa"), ("aU", "aa"), ("a", "aa"), ("A", "aa"), ("V", "aa"),
                ("eI", "e"), ("e", "e"), ("E", "e"), ("3", "e"), ("@", "e"),
                ("i", "i"), ("I", "i"), ("j", "i"),
                ("oU", "o"), ("O", "o"), ("o", "o"), ("0", "o"),
                ("u", "u"), ("U", "u"))


def script_phones(text: str, language: str = "en-us") -> list[list[str]]:
    """The script's words, each as its phones' mouth shapes (``SHAPES``), by espeak-ng."""
    espeak = shutil.which("espeak-ng")
    if espeak is None:
        raise DeviceError("a script needs espeak-ng to read it (Debian/Ubuntu: sudo apt-get install espeak-ng)")
    done = subprocess.run([espeak, "-q", "-x", "--sep= ", "-v", language, text], capture_output=True, text=True,
                          check=False, timeout=60)
    if done.returncode != 0 or not done.stdout.strip():
        why = done.stderr.strip().splitlines()[-1:] or ["no phones"]
        raise DeviceError(f"espeak-ng could not read the script in {language!r}: {why[0]}")
    words = []
    for word in done.stdout.replace("\n", "  ").split("  "):
        shapes = [shape_of(phone) for phone in word.split()]
        if shapes:
            words.append(shapes)
    return words


def shape_of(phone: str) -> str:
    """The mouth shape an espeak-ng phone needs (stress marks ignored)."""
    name = phone.lstrip("',%=")
    if name in PHONE_SHAPES:
        return PHONE_SHAPES[name]
    for start, shape in VOWEL_STARTS:
        if name.startswith(start):
            return shape
    return "other"


def shape_scores(readings: Sequence[Mapping[str, float]]) -> np.ndarray:
    """(blocks, shapes) log-probabilities that each block sounds like each shape."""
    out = np.empty((len(readings), len(SHAPES)))
    for t, r in enumerate(readings):
        speech = min(1.0, 2.0 * r["level"])
        vowels = sum(r[v] for v in VOWELS) or 1.0
        hiss = (r["ss"] + r["ff"]) / max(r["level"], 1e-3)
        voiced = speech * r["voiced"]
        share = {v: r[v] / vowels for v in VOWELS}
        share["o"], share["u"] = share["o"] + 0.5 * share["u"], share["u"] + 0.5 * share["o"]  # rounded alike
        p = {v: voiced * (0.15 + 0.85 * min(1.0, share[v])) for v in VOWELS}
        murmur = voiced * (r["u"] + 0.5 * r["o"]) / vowels  # an m or b hums through closed lips, like an oo
        p.update(closed=0.6 * (1.0 - speech) + 0.3 * murmur + 0.05, silence=1.0 - speech,
                 ss=speech * min(1.0, hiss) * (0.3 + r["ss"] / max(r["ss"] + r["ff"], 1e-6)),
                 ff=speech * min(1.0, hiss) * (0.3 + r["ff"] / max(r["ss"] + r["ff"], 1e-6)) + 0.1 * (1 - speech),
                 other=0.35 * speech + 0.1)
        out[t] = [math.log(max(FLOOR, min(1.0, p[shape]))) for shape in SHAPES]
    return out


def align(readings: Sequence[Mapping[str, float]], words: list[list[str]]) -> list[str]:
    """Each block's shape: the script's phones laid over the readings in order (Viterbi)."""
    states = _states(words)
    if not readings:
        return []
    scores = shape_scores(readings)[:, [SHAPES.index(shape) for shape, _, _ in states]]
    n = len(states)
    stay = np.array([can_stay for _, can_stay, _ in states])
    skip_from = np.array([skippable for _, _, skippable in states])
    to = np.arange(n)
    sources = np.stack([to, to - 1, to - 2])  # stay, advance, jump over an optional silence
    best = np.full(n, -np.inf)
    best[0] = scores[0, 0]
    if skip_from[0] and n > 1:
        best[1] = scores[0, 1]
    back = np.zeros((len(readings), n), dtype=np.int32)
    values = np.full((3, n), -np.inf)
    for t in range(1, len(readings)):
        values[0] = np.where(stay, best, -np.inf)
        values[1, 1:] = best[:-1]
        values[2, 2:] = np.where(skip_from[1:-1], best[:-2], -np.inf)
        which = np.argmax(values, axis=0)
        best = values[which, to] + scores[t]
        back[t] = sources[which, to]
    ends = [n - 1] + ([n - 2] if skip_from[n - 1] else [])
    state = max(ends, key=lambda k: best[k])
    path = [state]
    for t in range(len(readings) - 1, 0, -1):
        state = int(back[t, state])
        path.append(state)
    return [states[k][0] for k in reversed(path)]


def _states(words: list[list[str]]) -> list[tuple[str, bool, bool]]:
    """(shape, may stay, may be skipped) per state: an optional silence before, between and after
    the words, and each phone as its shortest run of states, only the last of which may stay."""
    states = [("silence", True, True)]
    for word in words:
        for shape in word:
            states += [(shape, False, False)] * (MIN_BLOCKS.get(shape, SHORTEST) - 1) + [(shape, True, False)]
        states.append(("silence", True, True))
    return states


def scripted(readings: list[dict[str, float]], words: list[list[str]]) -> list[dict[str, float]]:
    """The readings with the script's shapes where they were aligned: each vowel, closure and hiss
    channel becomes its aligned phone's (at the voice's loudness), ``round`` and ``wide`` follow
    the aligned vowel, and a pressed closure shuts ``open``."""
    out = []
    for reading, shape in zip(readings, align(readings, words)):
        r = dict(reading)
        strength = max(r["level"], 0.3) if shape != "silence" else 0.0
        for name in (*VOWELS, "ss", "ff"):
            r[name] = strength if name == shape else 0.0
        r["closed"] = 1.0 if shape == "closed" else 0.0
        r["round"] = strength if shape in ("o", "u") else 0.0
        r["wide"] = strength if shape in ("i", "e") else 0.0
        if shape == "closed":
            r["open"] = 0.0
        out.append(r)
    return out
