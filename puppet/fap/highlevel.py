"""High-level FAPs: visemes (FAP 1) and expressions (FAP 2) as sets of low-level FAPs.

The shapes are ``puppet/data/high_level_faps.yaml`` (the file says how each was chosen); a frame's
blends follow the standard and add to its low-level FAPs. FAP 1 / 2 fields read from a file are
held to what they can mean (``limit_fields``) when they are shown, never in the file.
"""

from __future__ import annotations

import functools
import importlib.resources
from collections.abc import Mapping

import numpy as np
import yaml

from puppet.fap.table import N_FAPS, fap


@functools.lru_cache(maxsize=1)
def high_level_faps() -> dict[str, dict[int, np.ndarray]]:
    """Visemes 0-14 and expressions 0-6 (0 = none) as 68-value arrays, from the data file."""
    text = importlib.resources.files("puppet").joinpath("data", "high_level_faps.yaml").read_text("utf-8")
    data = yaml.safe_load(text)
    out: dict[str, dict[int, np.ndarray]] = {"visemes": {}, "expressions": {0: np.zeros(N_FAPS)}}
    for kind in ("visemes", "expressions"):
        for number, shape in data[kind].items():
            values = np.zeros(N_FAPS)
            for name, value in (shape or {}).items():
                values[fap(name).number - 1] += float(value)
            out[kind][int(number)] = values
    for kind, top in (("visemes", 14), ("expressions", 6)):
        missing = sorted(set(range(top + 1)) - set(out[kind]))
        if missing:
            raise ValueError(f"high_level_faps.yaml: {kind} {missing} are not defined")
    return out


def expand(values: np.ndarray, viseme: tuple[float, ...] | None = None,
           expression: tuple[float, ...] | None = None) -> np.ndarray:
    """The 68 values with FAP 1 / FAP 2 expanded into low-level FAPs and added.

    ``viseme`` is (select1, select2, blend); ``expression`` is (select1, intensity1, select2,
    intensity2); both as in a .fap file. The def / init_face flags of a .fap file (new viseme or
    expression definitions sent in the stream) are not used: the shapes come from the data file.
    """
    shapes = high_level_faps()
    out = np.array(values, dtype=float)
    if out[:2].any():
        raise ValueError("FAP 1 and 2 are not values: pass them as viseme=(select1, select2, blend) "
                         "and expression=(select1, intensity1, select2, intensity2)")
    _check_selects(viseme, expression)
    if viseme is not None:
        s1, s2, blend = viseme[:3]
        out += shapes["visemes"][int(s1)] * (blend / 63) + shapes["visemes"][int(s2)] * (1 - blend / 63)
    if expression is not None:
        s1, i1, s2, i2 = expression[:4]
        out += shapes["expressions"][int(s1)] * (i1 / 63) + shapes["expressions"][int(s2)] * (i2 / 63)
    return out


def limit_fields(viseme: np.ndarray | None,
                 expression: np.ndarray | None) -> tuple[tuple[float, ...] | None, tuple[float, ...] | None]:
    """FAP 1 / 2 fields as read from a file, held to what they can mean: a select naming no
    viseme (0-14) or expression (0-6) selects none, blends and intensities are held to 0-63."""
    held_viseme: tuple[float, ...] | None = None
    held_expression: tuple[float, ...] | None = None
    if viseme is not None:
        s1, s2, blend = (float(x) for x in viseme[:3])
        held_viseme = (_select(s1, 14), _select(s2, 14), min(max(blend, 0.0), 63.0))
    if expression is not None:
        s1, i1, s2, i2 = (float(x) for x in expression[:4])
        held_expression = (_select(s1, 6), min(max(i1, 0.0), 63.0), _select(s2, 6), min(max(i2, 0.0), 63.0))
    return held_viseme, held_expression


def _select(value: float, top: int) -> int:
    return int(value) if 0 <= value <= top else 0


def fap_values(faps_by_key: Mapping[int | str, float]) -> np.ndarray:
    """A 68-value array from {number or name: value}; unknown keys name the closest FAP."""
    values = np.zeros(N_FAPS)
    for key, value in faps_by_key.items():
        number = fap(key).number
        if number in (1, 2):
            raise ValueError(f"FAP {number} ({fap(number).name}) is not a value: pass it as "
                             f"{'viseme=(select1, select2, blend)' if number == 1 else 'expression=(select1, intensity1, select2, intensity2)'}")
        values[number - 1] = float(value)
    return values


def _check_selects(viseme: tuple[float, ...] | None, expression: tuple[float, ...] | None) -> None:
    """Viseme selects 0-14 and expression selects 0-6, as FAP 1 / FAP 2 define them."""
    for name, fields, top in (("viseme", viseme, 14), ("expression", expression, 6)):
        if fields is None:
            continue
        selects = [fields[0], fields[2]] if name == "expression" else list(fields[:2])
        bad = [s for s in selects if not (0 <= int(s) <= top)]
        if bad:
            raise ValueError(f"{name} {bad[0]} does not exist: {name}s are numbered 0 to {top}")
