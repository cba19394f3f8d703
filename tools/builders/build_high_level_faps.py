"""Rewrite the six expressions and the rounded visemes O (13) and U (14) of
puppet/data/high_level_faps.yaml from their FACS recipes (puppet/fap/facs.py).

Each recipe is a weighted sum of the artist's ARKit shapes of the default face
(``../shared/assets/makehuman/faceunits_arkit``). Its FAPs are fitted to that summed shape on the
shipped rig (``fit_faps`` over the whole skin, within the face's limits; the eyeballs held still,
and the lips' mid-line where the jaw does not drop: ``MIDLIP``; in joy the lip corners first, then
the rest around them: ``CORNERS_FIRST``; the lip corners' raise past the Greta editor's slider
end, ``CORNERS_RAISED``; joy's lift_cheek lowered until the skin under the eyes bends no more than
``CHEEK_CREASE``, the rest refitted around it: ``within_crease``), made left/right symmetric,
rounded to whole FAPU, and then eased where the sum folds (unless it raises the corners past the
editor's end and folds only what the fold guard holds, ``held_by_guard``: joy): while a triangle
is turned over, the FAP pair (a FAP and its mirror) whose easing to 90% unfolds most is eased (the
artist's joy itself folds a few triangles where cheek and smile meet). What is written is what the
face shows (``FapEngine.shown``: an eased lip FAP's twin follows it). Run
``tools/builders/build_default_rig.py`` after it: the rig's guard watches what these shapes fold.

Fitting the sum beat summing the shapes' own fits (``arkit_faps.json``, eyeballs zeroed): before
easing, the fit left less of the sum unexplained in 7 of the 8 shapes (median 0.37 against 0.40;
joy 0.53 against 0.57, O 0.38 against 0.45; U alone 0.37 against 0.35), and the summed fits pass
the face's limits where two shapes add (joy's by up to 298 FAPU).

Everything from the marker line of the YAML file to its end is written here; the hand-made
visemes 0-12 above it are kept. Prints each shape's relative residual |V(f) - V0 - D| / |D|
against the summed artist shape, before (the table as it was) and after.

    PYTHONPATH=. .venv/bin/python tools/builders/build_high_level_faps.py [--check]
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import numpy as np
import yaml

import puppet
from puppet.bench.assets import shared_assets
from puppet.face.autorig import rig_for_face
from puppet.face.examples import load_examples
from puppet.fap.facs import EXPRESSIONS, VISEMES, artist_shape, describe
from puppet.fap.highlevel import high_level_faps
from puppet.fap.table import N_FAPS, clamp_ranges, fap
from puppet.runtime import creaselimit
from puppet.runtime.creases import largest_bend_near
from puppet.runtime.fapcalibration import fit_faps, mirror_fap, relative_residual
from puppet.runtime.musclesolver import folded_triangles
from puppet.runtime.runtime import Runtime

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "puppet" / "data" / "high_level_faps.yaml"
MARKER = "  # -- from here to the end: written by tools/builders/build_high_level_faps.py from puppet/fap/facs.py --\n"
EYEBALLS = (23, 24, 25, 26)
"""The gaze FAPs, held at 0: an expression does not turn the eyes."""
MIDLIP = (4, 5, 51, 52)
"""The lips' vertical FAPs on the mid-line, held at 0 in an expression that does not drop the jaw
(FACS unit 26): it leaves the lips' opening to the visemes, so that p/b/m still closes them while
smiling (the artist's smile lifts the lower lip 170 MNS past the upper one at the mid-line)."""
UPPER_LIP_SIDES = (8, 9, 55, 56)
"""The upper lip's points midway to the corners (2.6, 2.7, 8.5, 8.6), held at 0 while joy's lip
corners are fitted (``CORNERS_FIRST``): fitted together, the upper lip beside the corners rises
instead of them, which turns the smile into a pout (docs/realism_facs.png shows the smile)."""
LIFT_CHEEKS = (41, 42)
"""lift_l_cheek and lift_r_cheek: their calibrated motion lifts the cheekbone's point (5.3, 5.4)
faster than the skin around it, so that past about 100 ENS in joy the skin under each eye bends
along a line, a bright crease (at the 167 ENS joy's fit gives them: 56 degrees; the artist's
smile: 8). Joy keeps them within ``CHEEK_CREASE`` (``within_crease``)."""
CHEEK_CREASE = np.degrees(creaselimit.BOUND)
"""Degrees: the most a shape may bend a skin edge near the cheekbones beyond its rest angle, as at
pose time (``puppet.runtime.creaselimit``; the artist's smile bends them 8, joy without lift_cheek 13)."""
CREASE_BOUNDED = {("expressions", 1): LIFT_CHEEKS}
"""Shapes whose FAPs named here are lowered until the cheeks bend no more than ``CHEEK_CREASE``
(the pose-time limit then leaves them as they are, and the rest of the shape is refitted around them)."""
CREASE_STEPS = 6
"""Halvings of the share of their fitted value that crease-bounded FAPs keep."""
CREASE_ROUNDS = 3
"""Times the crease-bounded FAPs are lowered and the rest refitted before they are dropped."""
CORNERS_FIRST = {("expressions", 1): UPPER_LIP_SIDES}
"""Shapes whose lip corners are fitted first, with these FAPs held too, and the rest of the shape
fitted again around the corners with them free (``around``): joy's corners lift 12.2 mm
(the artist's 13.2), and the upper lip beside them rises with them. Held at 0 throughout, the
lower lip rose 7 mm past the upper lip's inner edge beside the corners (the artist's: 1.3 mm);
fitted with the corners, the corners lifted 11.1 mm."""
ACROSS = (15, 64)
"""shift_jaw and bend_nose: a symmetric shape has none (their mirror is their negative)."""
SMALLEST = 5
"""FAPU: smaller values are left out of the table."""
EASE = 0.9
"""The share of its value a FAP pair keeps at each easing step (``unfolded``)."""
CORNERS_RAISED = (12, 13, 59, 60)
"""raise_l/r_cornerlip and their outer twins, fitted past the Greta editor's 600 MNS slider end,
within the face's own reach (``fit_faps``' ``past_editor``): the artist's smile lifts the corners
746 MNS, and capped at 600 joy's lifted them 9.3 mm of the artist's 13.2."""
GUARD_MOVE = 0.015
"""dm: the most the fold guard may move a vertex to hold a pose's folds (``held_by_guard``)."""


def symmetric(values: np.ndarray) -> np.ndarray:
    """The mean of ``values`` and their mirror image (each FAP and its _l_/_r_ twin), in whole FAPU."""
    twin = np.array([fap(mirror_fap(fap(n).name)).number - 1 for n in range(1, N_FAPS + 1)])
    out = (values + values[twin]) / 2
    out[[n - 1 for n in ACROSS]] = 0
    out = np.round(out)
    out[np.abs(out) < SMALLEST] = 0
    return out


def folds(runtime: Runtime, values: np.ndarray) -> tuple[int, float]:
    """(turned-over triangles, how far they turned: the sum of their negative normal cosines)."""
    triangles = np.asarray(runtime.face.triangles)

    def unit_normals(x: np.ndarray) -> np.ndarray:
        n = np.cross(x[triangles[:, 1]] - x[triangles[:, 0]], x[triangles[:, 2]] - x[triangles[:, 0]])
        return n / np.maximum(np.linalg.norm(n, axis=1), 1e-30)[:, None]

    cos = np.einsum("ij,ij->i", unit_normals(runtime.deform_faps(values)), unit_normals(runtime.rest))
    return int((cos < 0).sum()), float(np.maximum(-cos, 0).sum())


def held_by_guard(runtime: Runtime, values: np.ndarray) -> bool:
    """Whether the face shows the pose without a fold: nothing folds, or the fold guard
    (``puppet.runtime.sliverguard``) watching the triangles it folds holds them all, moving no
    vertex more than ``GUARD_MOVE``. The shipped rig watches what the shipped poses fold (its
    ``guarded``, listed by ``tools/builders/build_default_rig.py`` from this table; ``runtime``
    watches none, ``fitting_runtime``): joy's lip corners raised as far as the artist's smile
    fold a few hidden slivers inside the corners, which the guard holds by moving them at most a
    millimetre."""
    triangles = np.asarray(runtime.face.triangles)
    plain = runtime.deform_faps(values)
    turned = folded_triangles(runtime.rest, plain, triangles)
    if not turned.any():
        return True
    rig = copy.copy(runtime.rig)
    rig.guarded = np.unique(triangles[turned])
    shown = Runtime(runtime.face, rig, dtype=runtime.dtype).deform_faps(values)
    return not folded_triangles(runtime.rest, shown, triangles).any() and \
        float(np.linalg.norm(shown - plain, axis=1).max()) <= GUARD_MOVE


def past_editor(values: np.ndarray) -> bool:
    """Whether ``values`` take a lip corner past the Greta editor's slider end (``clamp_ranges``):
    within it, the face's own fold-free reach holds every pose without the guard's help."""
    low, high = clamp_ranges()
    index = [n - 1 for n in CORNERS_RAISED]
    return bool(np.any(values[index] > high[index]) or np.any(values[index] < low[index]))


def unfolded(runtime: Runtime, values: np.ndarray) -> np.ndarray:
    """``values`` as they are where they raise the lip corners past the editor's end and the face
    shows them without a fold (``held_by_guard``), else with FAP pairs eased to ``EASE`` of their
    value, one pair at a time, the pair that unfolds most first, until nothing folds."""
    if past_editor(values) and held_by_guard(runtime, values):
        return values
    values = values.copy()
    while folds(runtime, values)[0]:
        pairs = {tuple(sorted({n, fap(mirror_fap(fap(n + 1).name)).number - 1})) for n in np.flatnonzero(values)}
        candidates = []
        for pair in sorted(pairs):
            eased = values.copy()
            eased[list(pair)] = np.round(eased[list(pair)] * EASE)
            candidates.append((folds(runtime, eased), pair, eased))
        values = min(candidates, key=lambda c: (c[0], c[1]))[2]
    return values


def around(runtime: Runtime, shape: np.ndarray, first: np.ndarray, kept: tuple[int, ...],
           held: tuple[int, ...]) -> np.ndarray:
    """``first``'s FAPs ``kept``, with every other FAP fitted again (``held`` kept at 0) to what
    those leave of ``shape``."""
    fixed = np.zeros(N_FAPS)
    index = [n - 1 for n in kept]
    fixed[index] = first[index]
    left = shape - (runtime.deform_faps(fixed) - runtime.deform_faps(np.zeros(N_FAPS)))
    return fixed + fit_faps(runtime, left, held=held + kept)


def cheek_crease(runtime: Runtime, values: np.ndarray) -> float:
    """The largest bend (degrees) near the cheekbones in the pose ``values``."""
    return largest_bend_near(runtime.face, runtime.deform_faps(values), tuple(creaselimit.LIMITED.values()),
                             creaselimit.NEAR)


def within_crease(runtime: Runtime, shape: np.ndarray, values: np.ndarray, bounded: tuple[int, ...],
                  kept: tuple[int, ...], held: tuple[int, ...]) -> np.ndarray:
    """``values`` with the FAPs ``bounded`` lowered to the largest share of their value
    (``CREASE_STEPS`` halvings) that bends the cheeks no more than ``CHEEK_CREASE``, and the
    FAPs other than those and ``kept`` fitted again around them; again while the refit bends
    them more (``CREASE_ROUNDS`` at most, then the bounded FAPs are dropped)."""
    index = [n - 1 for n in bounded]
    for _ in range(CREASE_ROUNDS):
        if cheek_crease(runtime, values) <= CHEEK_CREASE:
            return values
        good, bad = 0.0, 1.0
        for _ in range(CREASE_STEPS):
            share = (good + bad) / 2
            trial = values.copy()
            trial[index] = np.round(values[index] * share)
            good, bad = (share, bad) if cheek_crease(runtime, trial) <= CHEEK_CREASE else (good, share)
        lowered = values.copy()
        lowered[index] = np.round(values[index] * good)
        values = symmetric(around(runtime, shape, lowered, kept + bounded, held))
    if cheek_crease(runtime, values) <= CHEEK_CREASE:
        return values
    values[index] = 0
    return symmetric(around(runtime, shape, values, kept + bounded, held))


def build(runtime: Runtime, examples: dict[str, np.ndarray]) -> dict[str, dict[int, np.ndarray]]:
    """{"expressions" / "visemes": {number: 68 FAP values}} for every recipe of ``puppet.fap.facs``."""
    def values(kind: str, number: int, units: dict[int, float]) -> np.ndarray:
        held = EYEBALLS + (MIDLIP if kind == "expressions" and 26 not in units else ())
        shape = artist_shape(examples, units)
        first = CORNERS_FIRST.get((kind, number))
        bounded = CREASE_BOUNDED.get((kind, number), ())
        fitted = fit_faps(runtime, shape, held=held + (first + bounded if first else ()), past_editor=CORNERS_RAISED)
        if first:
            fitted = around(runtime, shape, symmetric(fitted), CORNERS_RAISED, held)
        if bounded:
            fitted = within_crease(runtime, shape, symmetric(fitted), bounded, CORNERS_RAISED if first else (), held)
        eased = unfolded(runtime, symmetric(fitted))
        return np.round(runtime.faps.shown(eased))  # the lip pairs as they follow each other on the face

    return {kind: {number: values(kind, number, units) for number, (_, units) in recipes.items()}
            for kind, recipes in (("expressions", EXPRESSIONS), ("visemes", VISEMES))}


def fitting_runtime(face) -> Runtime:
    """The face's rig without its ``guarded`` list: the shapes are fitted, and what they fold is
    found, on the rig as its motions and limits make it, not as the guard bent it for the table
    before (the rig then lists what this table folds, so the table is the same when rebuilt)."""
    rig = copy.copy(rig_for_face(face))
    rig.guarded = np.zeros(0, dtype=np.int64)
    return Runtime(face, rig, dtype=np.float64)


def entry(number: int, name: str, units: dict[int, float], values: np.ndarray, residual: float) -> str:
    lines = [f"  {number}:{'':<{22 - len(str(number))}}# {name}: {describe(units)}",
             f"    # (FACS units as the artist's ARKit shapes; residual {residual:.2f} against their sum)"]
    lines += [f"    {fap(n + 1).name}: {int(values[n])}" for n in np.flatnonzero(values)]
    return "\n".join(lines) + "\n"


def write(table: Path, built: dict, residuals: dict) -> None:
    """Everything after ``MARKER`` in ``table`` replaced by the built visemes, then the expressions."""
    text = table.read_text("utf-8")
    if MARKER not in text:
        raise SystemExit(f"{table}: no marker line {MARKER.strip()!r}")
    out = text[:text.index(MARKER) + len(MARKER)]
    for number, (name, units) in VISEMES.items():
        out += entry(number, name, units, built["visemes"][number], residuals[("visemes", number)])
    out += "\nexpressions:\n"
    for number, (name, units) in EXPRESSIONS.items():
        out += entry(number, name, units, built["expressions"][number], residuals[("expressions", number)])
    yaml.safe_load(out)
    table.write_text(out, "utf-8")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="print the residuals; write nothing")
    args = parser.parse_args(argv)
    face = puppet.load_face()
    runtime = fitting_runtime(face)
    examples = load_examples(face, shared_assets() / "makehuman" / "faceunits_arkit")
    built = build(runtime, examples)
    before = high_level_faps()
    residuals = {}
    print("relative residual |V(f)-V0-D|/|D| against the summed artist shape: before -> after (folds after)")
    for kind, recipes in (("expressions", EXPRESSIONS), ("visemes", VISEMES)):
        for number, (name, units) in recipes.items():
            D = artist_shape(examples, units)
            residuals[(kind, number)] = relative_residual(runtime, built[kind][number], D)
            turned = folds(runtime, built[kind][number])[0]
            print(f"  {kind[:-1]} {number:>2} {name:<9} {relative_residual(runtime, before[kind][number], D):.3f} -> "
                  f"{residuals[(kind, number)]:.3f}   ({turned} folds, {'held by the guard' if turned else 'none shown'})")
    if not args.check:
        write(TABLE, built, residuals)
        print(f"{TABLE}: expressions 1-6 and visemes {', '.join(map(str, VISEMES))} written")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
