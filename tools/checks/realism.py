"""Print the rig's realism figures and draw contact sheets of its poses.

    .venv/bin/python tools/checks/realism.py [--json] [--no-images] [--expressions-only] [--out docs]

Measures the default face (``puppet.load_face()``) against the ARKit example shapes in
``../shared/assets/makehuman/faceunits_arkit`` (``$FACEPUPPET_SHARED``; all-zero shapes such as
tongueOut are skipped and named):

1. **Fit residual** |V(f) - V0 - D| / |D| over the vertices a shape moves
   (``puppet.runtime.fapcalibration``), median and worst, with the FAPs fitted on the moved vertices and
   on the whole skin: on the shipped (calibrated) rig, on the coarse uncalibrated rig
   (``build_rig(grid=False, calibrated=False)``) as a baseline, and on rigs calibrated here
   without some shapes (held-out and training shapes reported apart): the side split
   (``HELD_OUT_SIDE``, every right shape, predicted through the mirror tie from the left ones)
   and the group split (``HELD_OUT``, whole pairs and groups: motions no example showed). **Capacity**:
   the residual with every control point free, on the shipped and the coarse rig.
2. **Folds** (triangles whose normal turns against its rest normal) of the shipped rig for each
   FAP 3..68 alone at both ends of its range, for expressions 1..6 at intensity 63 and for
   visemes 0..14; and, as information, in the rig's fit of each ARKit shape.
3. **Open mouth**: dark and teeth pixels inside the inner lip line at open_jaw 400
   (``puppet.view.mouthcheck``).
4. **Targets**: met or missed for each.

Images (unless ``--no-images``), in ``--out``: ``realism.png`` (each ARKit shape, the example
beside the shipped rig's fit, front view; held-out shapes marked), ``realism_expressions.png``
(expressions, visemes and the open mouth on the shipped rig, front and three-quarter) and
``realism_facs.png`` (each expression and the visemes O and U: the artist's shapes for its FACS
units summed, ``puppet.fap.facs``, beside the rig, front and three-quarter).
``--json`` prints the figures as one JSON document instead of the table. About 27 minutes on
2 busy CPU cores (the two held-out calibrations are most of it); ``--expressions-only`` measures
nothing and draws only the last two sheets.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

import puppet
from puppet.bench.assets import shared_assets
from puppet.face.autorig import build_rig
from puppet.face.examples import load_examples
from puppet.fap.facs import EXPRESSIONS as FACS_EXPRESSIONS
from puppet.fap.facs import VISEMES as FACS_VISEMES
from puppet.fap.facs import artist_shape
from puppet.fap.table import clamp_ranges, fap
from puppet.runtime.fapcalibration import HELD_OUT, HELD_OUT_SIDE, calibrate, capacity, fit_faps, relative_residual
from puppet.runtime.foldlimits import within_limits
from puppet.runtime.musclesolver import folded_triangles
from puppet.view.mouthcheck import mouth_pixels
from puppet.view.renderer import Renderer

EXPRESSIONS = ("joy", "sadness", "anger", "fear", "disgust", "surprise")
VISEMES = range(15)
OPEN_JAW = 400.0
TARGETS = {"held-out median (side)": 0.30, "held-out median (groups)": 0.30, "capacity median": 0.20,
           "folds": 0, "open mouth dark": 0.25, "open mouth teeth": 0.08}
AT_MOST = {"held-out median (side)", "held-out median (groups)", "capacity median", "folds"}
"""Targets that are upper limits; the others are lower limits."""
TILE = 200
COLUMNS = 6
MARGIN = 1.2
"""Framing: the face oval (``face.contours["face_oval"]``) and this much room, for the open jaw."""


# -- figures --------------------------------------------------------------------------------------

def summary(residuals: dict[str, float]) -> dict:
    """Median and worst (with its name) of {name: residual}."""
    worst = max(residuals, key=residuals.get)
    return {"median": float(np.median(list(residuals.values()))), "worst": residuals[worst],
            "worst_name": worst, "n": len(residuals)}


def fits(runtime, examples: dict[str, np.ndarray], where: str) -> dict[str, np.ndarray]:
    """{name: the 68 FAP values ``fit_faps(where=...)`` gives for that example}."""
    return {name: fit_faps(runtime, D, where=where) for name, D in examples.items()}


def residuals(runtime, examples: dict[str, np.ndarray], values: dict[str, np.ndarray]) -> dict[str, float]:
    return {name: relative_residual(runtime, values[name], D) for name, D in examples.items()}


def capacities(runtime, examples: dict[str, np.ndarray]) -> dict[str, float]:
    return {name: capacity(runtime, D) for name, D in examples.items()}


SPLITS = {"side": HELD_OUT_SIDE, "groups": HELD_OUT}
"""The held-out splits: one side (the headline target) and whole groups."""


def held_out_fit(face, examples: dict[str, np.ndarray], held_out: tuple[str, ...]) -> dict:
    """Calibrate without ``held_out`` as the shipped rig is calibrated (``fold_safe_calibration``)
    and measure every shape on that rig within its fold limits; ``unlimited`` measures the same
    calibration before its fold limits (``Calibration.weights`` are already ``fit_faps``, whole
    skin, of every example)."""
    cal = calibrate(face, examples, held_out=held_out)
    out = {}
    for name, c in (("unlimited", cal), ("limited", within_limits(face, cal, examples))):
        fitted = residuals(puppet.Runtime(face, c.rig), examples, c.weights)
        held = {n: r for n, r in fitted.items() if n in cal.held_out}
        train = {n: r for n, r in fitted.items() if n not in cal.held_out}
        out[name] = {"held_out": summary(held), "training": summary(train)}
    return out["limited"] | {"unlimited": out["unlimited"]}


def fap_ends() -> list[tuple[int, float]]:
    """(FAP number, value) for FAPs 3..68 at each finite, non-zero end of their range."""
    lo, hi = clamp_ranges()
    return [(n, float(end)) for n in range(3, 69) for end in (lo[n - 1], hi[n - 1])
            if np.isfinite(end) and end != 0]


def fold_count(face, vertices: np.ndarray) -> int:
    return int(folded_triangles(face.vertices, vertices, face.triangles).sum())


def folds(face, runtime, fitted: dict[str, np.ndarray] | None = None) -> dict:
    """Folded triangles per FAP end, expression and viseme, and per ``fitted`` example pose
    {name: FAP values} (not a target); FAP ends and fits are listed only where they fold, worst first."""
    by_end = {}
    for number, value in fap_ends():
        values = np.zeros(68)
        values[number - 1] = value
        by_end[f"{number} {fap(number).name} {value:+g}"] = fold_count(face, runtime.deform_faps(values))
    by_fit = {name: fold_count(face, runtime.deform_faps(values)) for name, values in (fitted or {}).items()}
    return {"faps": {"total": sum(by_end.values()), "tested_ends": len(by_end),
                     "folding": len({k.split()[0] for k, n in by_end.items() if n}), "by_end": worst_first(by_end)},
            "expressions": {EXPRESSIONS[e - 1]: fold_count(face, runtime.deform_faps(expression=(e, 63, 0, 0)))
                            for e in range(1, 7)},
            "visemes": {str(v): fold_count(face, runtime.deform_faps(viseme=(v, 0, 63))) for v in VISEMES},
            "fits": worst_first(by_fit)}


def worst_first(counts: dict[str, int]) -> dict[str, int]:
    """The non-zero counts, largest first."""
    return {k: n for k, n in sorted(counts.items(), key=lambda kv: -kv[1]) if n}


def mouth(face, runtime) -> dict:
    m = mouth_pixels(face, runtime, open_jaw=OPEN_JAW)
    return {"open_jaw": OPEN_JAW, "area_px": m.area, "dark": m.dark_fraction, "teeth": m.teeth_fraction}


def targets(report: dict) -> dict[str, dict]:
    """Each target with its value and whether it is met."""
    fold_total = (report["folds"]["faps"]["total"] + sum(report["folds"]["expressions"].values())
                  + sum(report["folds"]["visemes"].values()))
    values = {"held-out median (side)": report["held_out"]["side"]["held_out"]["median"],
              "held-out median (groups)": report["held_out"]["groups"]["held_out"]["median"],
              "capacity median": report["capacity"]["shipped"]["median"],
              "folds": fold_total,
              "open mouth dark": report["mouth"]["dark"],
              "open mouth teeth": report["mouth"]["teeth"]}
    return {name: {"value": values[name], "target": limit,
                   "met": bool(values[name] <= limit if name in AT_MOST else values[name] >= limit)}
            for name, limit in TARGETS.items()}


def measure(face, shipped, examples: dict[str, np.ndarray]) -> tuple[dict, dict[str, np.ndarray]]:
    """The report, and the shipped rig's whole-skin fit of each example (for the images)."""
    coarse = puppet.Runtime(face, build_rig(face, grid=False, calibrated=False))
    report = {"fit": {}, "capacity": {}}
    for rig_name, runtime in (("shipped", shipped), ("coarse", coarse)):
        report["fit"][rig_name] = {}
        for where in ("moved", "skin"):
            values = fits(runtime, examples, where)
            report["fit"][rig_name][where] = summary(residuals(runtime, examples, values))
            if (rig_name, where) == ("shipped", "skin"):
                shipped_fit = values
        report["capacity"][rig_name] = summary(capacities(runtime, examples))
    report["held_out"] = {split: held_out_fit(face, examples, names) for split, names in SPLITS.items()}
    report["folds"] = folds(face, shipped, shipped_fit)
    report["mouth"] = mouth(face, shipped)
    report["targets"] = targets(report)
    return report, shipped_fit


# -- table ----------------------------------------------------------------------------------------

def row(label: str, s: dict) -> str:
    return f"  {label:<34} median {s['median']:.3f}   worst {s['worst']:.3f} ({s['worst_name']}, n={s['n']})"


def print_table(report: dict) -> None:
    print(f"ARKit examples: {report['examples']} used; skipped (all zero): {', '.join(report['skipped']) or 'none'}")
    print("Fit residual |V(f)-V0-D|/|D| over moved vertices")
    for rig_name in ("shipped", "coarse"):
        for where in ("moved", "skin"):
            print(row(f"{rig_name} rig, FAPs fit on {where}", report["fit"][rig_name][where]))
    for split in SPLITS:
        print(row(f"held out ({split}): held out", report["held_out"][split]["held_out"]))
        print(row(f"held out ({split}): training", report["held_out"][split]["training"]))
        unlimited = report["held_out"][split]["unlimited"]
        print(row("  before fold limits: held out", unlimited["held_out"]))
        print(row("  before fold limits: training", unlimited["training"]))
    print("Capacity (every control point free)")
    for rig_name in ("shipped", "coarse"):
        print(row(f"{rig_name} rig", report["capacity"][rig_name]))
    f = report["folds"]
    print(f"Folds (shipped rig): {f['faps']['total']} folded triangles over {f['faps']['tested_ends']} FAP ends, "
          f"{f['faps']['folding']} FAPs folding")
    for name, count in list(f["faps"]["by_end"].items())[:8]:
        print(f"  FAP {name}: {count}")
    print("  expressions: " + ", ".join(f"{k} {v}" for k, v in f["expressions"].items()))
    print("  visemes: " + ", ".join(f"{k}:{v}" for k, v in f["visemes"].items()))
    print(f"  fitted ARKit poses (not a target): {sum(f['fits'].values())} folded triangles in {len(f['fits'])} "
          "shapes; worst " + ", ".join(f"{k} {v}" for k, v in list(f["fits"].items())[:6]))
    m = report["mouth"]
    print(f"Open mouth (open_jaw {m['open_jaw']:g}): area {m['area_px']} px, dark {m['dark']:.1%}, teeth {m['teeth']:.1%}")
    print("Targets")
    for name, t in report["targets"].items():
        sign = "<=" if name in AT_MOST else ">="
        value = f"{t['value']:.3f}" if isinstance(t["value"], float) else str(t["value"])
        print(f"  {name:<24} {value:>7} {sign} {t['target']:<5} {'met' if t['met'] else 'MISSED'}")
    print(f"({report['seconds']:.0f} s)")


# -- images ---------------------------------------------------------------------------------------

def labelled(image: np.ndarray, text: str) -> Image.Image:
    """The render with ``text`` on a strip above it."""
    tile = Image.new("RGB", (image.shape[1], image.shape[0] + 14), "white")
    tile.paste(Image.fromarray(image), (0, 14))
    ImageDraw.Draw(tile).text((3, 1), text, fill="black")
    return tile


def sheet(tiles: list[Image.Image], columns: int) -> Image.Image:
    width, height = tiles[0].size
    rows = -(-len(tiles) // columns)
    out = Image.new("RGB", (columns * width, rows * height), "white")
    for k, tile in enumerate(tiles):
        out.paste(tile, ((k % columns) * width, (k // columns) * height))
    return out


def frame(renderer: Renderer, face, view: str) -> None:
    renderer.aim(face.vertices[face.contours["face_oval"]], view=view, margin=MARGIN)


def rig_render(renderer: Renderer, runtime, **pose) -> np.ndarray:
    """The shipped rig posed (``Runtime.deform_faps`` arguments), with the rig's own normals."""
    vertices = runtime.deform_faps(**pose)
    normals = runtime.normals(vertices, runtime.fap_controls(**pose)[1])
    return renderer.render(vertices, normals)


def arkit_sheet(renderer: Renderer, face, runtime, examples: dict[str, np.ndarray],
                fitted: dict[str, np.ndarray]) -> Image.Image:
    """Per shape: the example (normals computed from the mesh) and the rig's fit, front view."""
    frame(renderer, face, "front")
    tiles = []
    for name, D in examples.items():
        mark = "".join(f" [{split} held out]" for split, names in SPLITS.items() if name in names)
        example = renderer.render(face.vertices + D)
        rig = rig_render(renderer, runtime, fap=fitted[name])
        tiles += [labelled(example, f"{name}{mark}: example"), labelled(rig, "rig fit")]
    return sheet(tiles, 2 * COLUMNS)


def expression_sheet(renderer: Renderer, face, runtime) -> Image.Image:
    """Expressions, visemes and the open mouth, each front and three-quarter."""
    poses = ([(f"expression {e} {EXPRESSIONS[e - 1]}", {"expression": (e, 63, 0, 0)}) for e in range(1, 7)]
             + [(f"viseme {v}", {"viseme": (v, 0, 63)}) for v in VISEMES]
             + [(f"open_jaw {OPEN_JAW:g}", {"fap": {"open_jaw": OPEN_JAW}})])
    tiles = []
    for label, pose in poses:
        for view in ("front", "three_quarter"):
            frame(renderer, face, view)
            tiles.append(labelled(rig_render(renderer, runtime, **pose), f"{label} ({view.replace('_', '-')})"))
    return sheet(tiles, 2 * COLUMNS)


def facs_sheet(renderer: Renderer, face, runtime, examples: dict[str, np.ndarray]) -> Image.Image:
    """Per FACS-built shape (``puppet.fap.facs``: the expressions, visemes O and U), the artist's
    summed shape beside the rig at full intensity, front and three-quarter."""
    poses = ([(f"expression {n} {name}", units, {"expression": (n, 63, 0, 0)}) for n, (name, units) in FACS_EXPRESSIONS.items()]
             + [(f"viseme {n} {name}", units, {"viseme": (n, 0, 63)}) for n, (name, units) in FACS_VISEMES.items()])
    tiles = []
    for label, units, pose in poses:
        for view in ("front", "three_quarter"):
            frame(renderer, face, view)
            tiles += [labelled(renderer.render(face.vertices + artist_shape(examples, units)), f"{label}: artist"),
                      labelled(rig_render(renderer, runtime, **pose), f"rig ({view.replace('_', '-')})")]
    return sheet(tiles, 4)


def draw_images(face, runtime, examples: dict[str, np.ndarray], fitted: dict[str, np.ndarray] | None,
                out: Path) -> list[Path]:
    """The contact sheets in ``out``; without ``fitted`` the ARKit one (realism.png) is left as it is."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "realism_expressions.png", out / "realism_facs.png"]
    with Renderer.for_face(face, width=TILE, height=TILE) as renderer:
        expression_sheet(renderer, face, runtime).save(paths[0], optimize=True)
        facs_sheet(renderer, face, runtime, examples).save(paths[1], optimize=True)
        if fitted is not None:
            paths.append(out / "realism.png")
            arkit_sheet(renderer, face, runtime, examples, fitted).save(paths[-1], optimize=True)
    return paths


# -- main -----------------------------------------------------------------------------------------

def load(folder: Path):
    """The default face, its shipped rig, the non-zero examples and the names of the zero ones."""
    face = puppet.load_face()
    examples = load_examples(face, folder)
    kept = {name: D for name, D in examples.items() if np.any(D)}
    return face, puppet.Runtime(face), kept, sorted(set(examples) - set(kept))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    parser.add_argument("--no-images", action="store_true", help="skip the contact sheets")
    parser.add_argument("--out", type=Path, default=Path("docs"), help="folder for the PNGs (default docs)")
    parser.add_argument("--expressions-only", action="store_true",
                        help="measure nothing; draw only realism_expressions.png and realism_facs.png (about a minute)")
    args = parser.parse_args()
    start = time.perf_counter()
    face, shipped, examples, skipped = load(shared_assets() / "makehuman" / "faceunits_arkit")
    if args.expressions_only:
        for path in draw_images(face, shipped, examples, None, args.out):
            print(f"image: {path}")
        return
    figures, fitted = measure(face, shipped, examples)
    report = {"examples": len(examples), "skipped": skipped, **figures}
    if not args.no_images:
        report["images"] = [str(p) for p in draw_images(face, shipped, examples, fitted, args.out)]
    report["seconds"] = time.perf_counter() - start
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print_table(report)
        for path in report.get("images", []):
            print(f"image: {path}")


if __name__ == "__main__":
    main()
