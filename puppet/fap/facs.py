"""The six basic emotions and the rounded visemes as FACS action units, each unit as the ARKit
blendshapes that show it: the recipes ``tools/builders/build_high_level_faps.py`` turns into FAPs.

MPEG-4 names its six expressions (FAP 2) after Ekman's basic emotions but leaves their shapes to
the face model. Ekman and Friesen described each emotion's prototype in action units of the
Facial Action Coding System (FACS; EMFACS, Ekman, Friesen & Hager 2002): joy 6 + 12, sadness
1 + 4 + 15 (+ 17), anger 4 + 5 + 7 + 23/24, fear 1 + 2 + 4 + 5 + 7 + 20 + 26, disgust 9 + 15 + 16
(+ 10), surprise 1 + 2 + 5B + 26. ARKit's blendshapes are FACS units by another name (browInnerUp
is unit 1, mouthSmileLeft and Right together unit 12, ...), and the default face's artist made
all of them (``../shared/assets/makehuman/faceunits_arkit``), so each expression here is a sum of
that artist's shapes: what the artist's face does when it shows those units.

``intensity`` (0-1, the share of the artist's full shape) follows FACS's grades where a prototype
names one (5B, a slight lid raise, in surprise) and otherwise keeps a secondary unit below the
defining ones (sadness's brow lowerer at half, so the inner brows still rise; fear's and
surprise's jaw drops, which the visemes leave to speech, at a quarter and two fifths of the
artist's wide-open jaw).

The visemes O (13) and U (14) are rounded the same way: the lip funneler (22) and pucker (18),
with the jaw a little open for O.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


def _both(stem: str) -> dict[str, float]:
    return {f"{stem}Left": 1.0, f"{stem}Right": 1.0}


ACTION_UNITS: dict[int, tuple[str, dict[str, float]]] = {
    1: ("inner brow raiser", {"browInnerUp": 1.0}),
    2: ("outer brow raiser", _both("browOuterUp")),
    4: ("brow lowerer", _both("browDown")),
    5: ("upper lid raiser", _both("eyeWide")),
    6: ("cheek raiser", _both("cheekSquint")),
    7: ("lid tightener", _both("eyeSquint")),
    9: ("nose wrinkler", _both("noseSneer")),
    10: ("upper lip raiser", _both("mouthUpperUp")),
    12: ("lip corner puller", _both("mouthSmile")),
    15: ("lip corner depressor", _both("mouthFrown")),
    16: ("lower lip depressor", _both("mouthLowerDown")),
    17: ("chin raiser", {"mouthShrugLower": 1.0}),
    18: ("lip pucker", {"mouthPucker": 1.0}),
    20: ("lip stretcher", _both("mouthStretch")),
    22: ("lip funneler", {"mouthFunnel": 1.0}),
    24: ("lip pressor", _both("mouthPress")),
    26: ("jaw drop", {"jawOpen": 1.0}),
}
"""FACS action unit -> (its name, the ARKit blendshapes that show it, at full strength)."""

EXPRESSIONS: dict[int, tuple[str, dict[int, float]]] = {
    1: ("joy", {6: 1.0, 12: 1.0}),
    2: ("sadness", {1: 1.0, 4: 0.5, 15: 1.0, 17: 0.4}),
    3: ("anger", {4: 1.0, 5: 0.4, 7: 0.7, 24: 1.0}),
    4: ("fear", {1: 1.0, 2: 0.6, 4: 0.4, 5: 1.0, 20: 1.0, 26: 0.25}),
    5: ("disgust", {9: 1.0, 10: 0.5, 15: 0.6, 16: 0.3}),
    6: ("surprise", {1: 1.0, 2: 1.0, 5: 1.0, 26: 0.4}),
}
"""MPEG-4 expression number -> (its name, {action unit: intensity})."""

VISEMES: dict[int, tuple[str, dict[int, float]]] = {
    13: ("O", {22: 1.0, 26: 0.3}),
    14: ("U", {18: 1.0, 22: 0.3}),
}
"""MPEG-4 viseme number -> (its sound, {action unit: intensity}): the rounded vowels."""


def blendshapes(units: Mapping[int, float]) -> dict[str, float]:
    """{ARKit blendshape: weight} that shows ``units`` ({action unit: intensity})."""
    out: dict[str, float] = {}
    for unit, intensity in units.items():
        for name, weight in ACTION_UNITS[unit][1].items():
            out[name] = out.get(name, 0.0) + intensity * weight
    return out


def artist_shape(examples: Mapping[str, np.ndarray], units: Mapping[int, float]) -> np.ndarray:
    """The artist's displacement (N, 3) for ``units``: the weighted sum of the example shapes
    ({ARKit name: (N, 3)}, ``puppet.face.examples.load_examples``) that show them."""
    weighted = (weight * np.asarray(examples[name]) for name, weight in blendshapes(units).items())
    shape: np.ndarray = sum(weighted)  # type: ignore[assignment]  # 0 only when no unit is set
    return shape


def describe(units: Mapping[int, float]) -> str:
    """The units in words: 'AU6 cheek raiser, AU12 lip corner puller x0.5'."""
    return ", ".join(f"AU{unit} {ACTION_UNITS[unit][0]}" + (f" x{intensity:g}" if intensity != 1 else "")
                     for unit, intensity in units.items())
