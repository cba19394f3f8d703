"""Zhou & Liu's experiment, reproduced: classic vs improved vs control-point muscles at large contraction.

Two meshes, one muscle each, contraction coefficients 0, 3, 5 and 10 (1 is the normal maximum):

* **grid**: a flat 41 x 41 vertex grid over the unit square, triangulated, with one linear muscle
  along x (fixed end at (-0.25, 0), insertion at (0.25, 0), both control points, alpha 30 deg, r_e 0.5, r_f 0.75, pull
  0.15 r_e as in the default muscles). Its control-point mode uses every 5th grid vertex in each
  direction (9 x 9 points) as control points and spreads their displacements over the grid by
  piecewise-linear interpolation on their Delaunay triangulation (``scipy LinearNDInterpolator``):
  a stand-in for DFFD on a flat sheet, where 3D Sibson coordinates are degenerate.
* **face**: the default face's left zygomatic major, every mode as the runtime draws it
  (``Runtime.deform_faps(muscles=..., mode=...)``): "control-point" is the runtime's control-point mode
  (the rig's active control points moved by ``control_point_displacements``, spread by DFFD, then
  the fold guard: the improved mode's edge constraints over the triangles those points reach);
  "control-point, no guard" is the same without the guard (DFFD alone), to show what it removes.
  On the grid the guard is the edge constraints run on the spread displacement.

Measured per case, over the skin triangles:

* **folded**: triangles whose normal turned against its rest normal (dot < 0);
* **overshoot**: the largest |displacement| / (rest distance to the fixed end) of the vertices
  within r_e / 4 of the fixed end; above 1 a vertex was dragged past the bone: the spike;
* **stretch**: the largest deformed / rest length of the edges with both ends in that ball.

A second table counts folded skin triangles for every default muscle alone at contraction 1, 3,
5 and 10 in each runtime mode. Without the guard no default muscle alone squeezes the skin at 0.5
(tests/test_muscles_runtime.py), and at 1 the risorius and the orbicularis oculi fold one triangle
each, at the lip and outer eye corners; with it nothing folds at 1 (nor all of them at 0.5). Beyond
that the guard and the improved mode's edge constraints are a safety net that always ends with no
corner within 5% of its opposite edge (``EdgeConstraints``: sweeps on a few rings of triangles
around the squeezed ones, then the displacement scaled back toward rest there), so the guarded
modes fold nothing at any contraction; classic Waters still does. That safety net has a price
the first table's overshoot column and the figure show: where it scales back (the zygomatic
major at 10 squeezes the skin where the dragged lip corner meets the nose's and cheek's fixed
borders), the lip corner ends nearer rest than at 5.

A third table has the median per-frame cost (``Runtime.deform_faps``, 50 frames, float32 runtime as in
the bench, each frame's contractions 0.1% off the last's: a held pose reuses the last frame's
muscle work, so this is a moving pose's cost) of the FAP path alone and of each muscle mode: every muscle at 0.5 and the zygomatic
pair at 1 (normal contractions: the guard only checks), the pair at 3 and the left one at 10
(beyond: the guard acts where the skin is squeezed).

Writes docs/muscle_experiment.png (rows: modes; columns: contractions; grids left, face crops right,
folded triangles red) and docs/muscle_experiment.md (the tables and per-frame timings on the default
face), and prints the tables. Run: ``PYTHONPATH=. .venv/bin/python tools/checks/muscle_experiment.py``.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from scipy.interpolate import LinearNDInterpolator

from puppet.face.load import load_face
from puppet.face.muscles import LinearMuscle, flat_grid
from puppet.runtime.musclesolver import EdgeConstraints, MuscleModel, control_point_displacements, folded_triangles
from puppet.runtime.runtime import Runtime
from puppet.runtime.skinsmoothing import skin_triangles

CONTRACTIONS = (0, 3, 5, 10)
MODES = ("classic", "improved", "control-point, no guard", "control-point")
RUNTIME_MODES = {"classic": "classic", "improved": "improved", "control-point": "control"}
DOCS = Path(__file__).resolve().parents[2] / "docs"
PANEL = 220
FACE_MUSCLE = "zygomatic_major_l"


GRID_MUSCLE = LinearMuscle("grid", np.array([-0.25, 0.0, 0.0]), np.array([0.25, 0.0, 0.0]), 30.0, 0.5, 0.75, 0.075)


def grid_cases() -> dict[str, dict[int, np.ndarray]]:
    """Deformed grid vertices per mode and contraction."""
    vertices, triangles = flat_grid()
    coarse = np.arange(41) % 5 == 0
    control = np.flatnonzero(np.logical_and.outer(coarse, coarse).ravel())
    edges = EdgeConstraints(vertices, triangles)
    out: dict[str, dict[int, np.ndarray]] = {m: {} for m in MODES}
    models = {m: MuscleModel(vertices, triangles, [GRID_MUSCLE], m) for m in ("classic", "improved")}
    for c in CONTRACTIONS:
        for mode, model in models.items():
            out[mode][c] = vertices + model.displace({"grid": c})
        d = control_point_displacements([GRID_MUSCLE], {"grid": c}, vertices[control])
        spread = LinearNDInterpolator(vertices[control, :2], d)(vertices[:, :2])
        out["control-point, no guard"][c] = vertices + spread
        edges.relax(spread)
        out["control-point"][c] = vertices + spread
    return out


def face_cases(runtime: Runtime, muscle: str = FACE_MUSCLE,
               contractions=CONTRACTIONS) -> dict[str, dict[int, np.ndarray]]:
    """Deformed face vertices per mode and contraction of one muscle, as the runtime draws them
    (and the control-point mode without its fold guard: DFFD of the moved control points alone)."""
    points = np.array([runtime.rig.point(n).position for n in runtime.control_points])
    out: dict[str, dict[int, np.ndarray]] = {m: {} for m in MODES}
    for c in contractions:
        for mode, runtime_mode in RUNTIME_MODES.items():
            out[mode][c] = runtime.deform_faps(muscles={muscle: c}, mode=runtime_mode)
        unguarded = control_point_displacements(runtime.rig.muscles, {muscle: c}, points, runtime.muscle_shares)
        out["control-point, no guard"][c] = runtime.deform(unguarded)
    return out


def every_muscle_table(face, runtime: Runtime, contractions=(1, 3, 5, 10)) -> str:
    """Markdown: folded skin triangles of every default muscle alone, per mode and contraction."""
    triangles = skin_triangles(face)
    head = "| muscle | " + " | ".join(f"{m} c={c}" for m in MODES for c in contractions) + " |"
    lines = [head, "|---|" + "---:|" * (len(MODES) * len(contractions))]
    for name in runtime.muscle_names:
        cases = face_cases(runtime, name, contractions)
        counts = [int(folded_triangles(face.vertices, cases[m][c], triangles).sum())
                  for m in MODES for c in contractions]
        lines.append(f"| {name} | " + " | ".join(map(str, counts)) + " |")
    return "\n".join(lines)


def spike(rest: np.ndarray, deformed: np.ndarray, triangles: np.ndarray, muscle: LinearMuscle) -> tuple[float, float]:
    """(overshoot, stretch) in the ball of radius r_e / 4 about the fixed end (module docstring)."""
    dist = np.linalg.norm(rest - muscle.fixed, axis=1)
    near = (dist < 0.25 * muscle.r_e) & (dist > 0)
    overshoot = float(np.max(np.linalg.norm(deformed - rest, axis=1)[near] / dist[near], initial=0.0))
    edges = np.unique(np.sort(np.r_[triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=1), axis=0)
    edges = edges[near[edges].all(axis=1)]
    ratio = (np.linalg.norm(deformed[edges[:, 0]] - deformed[edges[:, 1]], axis=1)
             / np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1))
    return overshoot, float(ratio.max(initial=0.0))


def table_rows(name: str, rest, triangles, muscle, cases) -> list[tuple]:
    rows = []
    for mode, by_c in cases.items():
        for c, deformed in by_c.items():
            folded = int(folded_triangles(rest, deformed, triangles).sum())
            rows.append((name, mode, c, folded, *spike(rest, deformed, triangles, muscle)))
    return rows


def markdown_table(rows: list[tuple]) -> str:
    lines = ["| mesh | mode | contraction | folded triangles | overshoot | stretch |", "|---|---|---:|---:|---:|---:|"]
    lines += [f"| {m} | {mode} | {c} | {f} | {o:.2f} | {s:.2f} |" for m, mode, c, f, o, s in rows]
    return "\n".join(lines)


# -- per-frame cost ------------------------------------------------------------------------------

def timings(runtime: Runtime, runs: int = 50) -> list[tuple[str, str, float]]:
    """Median per-frame milliseconds of ``Runtime.deform_faps`` on the default face for each mode and
    pose (module docstring), and no muscle as the baseline."""
    pair = ("zygomatic_major_l", "zygomatic_major_r")
    poses = {"every muscle at 0.5": dict.fromkeys(runtime.muscle_names, 0.5),
             "zygomatic major l+r at 1": dict.fromkeys(pair, 1.0),
             "zygomatic major l+r at 3": dict.fromkeys(pair, 3.0),
             "zygomatic_major_l at 10": {FACE_MUSCLE: 10.0}}
    frames = {"none (FAP path)": lambda pose: runtime.deform_faps()}
    frames |= {mode: lambda pose, m=m: runtime.deform_faps(muscles=pose, mode=m) for mode, m in RUNTIME_MODES.items()}
    out = []
    for pose_name, pose in poses.items():
        for mode, frame in frames.items():
            out.append((pose_name, mode, _median_ms(frame, pose, runs)))
    return out


def _median_ms(frame, pose: dict[str, float], runs: int) -> float:
    """Median ms of ``frame`` over ``runs`` poses alternating between ``pose`` and it 0.1% weaker."""
    weaker = {name: 0.999 * c for name, c in pose.items()}
    frame(pose)
    samples = []
    for i in range(runs):
        t = time.perf_counter()
        frame(weaker if i % 2 == 0 else pose)
        samples.append(time.perf_counter() - t)
    return 1e3 * statistics.median(samples)


# -- the figure -----------------------------------------------------------------------------------

def draw_panel(rest: np.ndarray, deformed: np.ndarray, triangles: np.ndarray, view: np.ndarray,
               box: tuple[float, float, float, float], wire: bool) -> Image.Image:
    """One panel: triangles seen along ``view`` (3x3 rows: screen x, screen y, toward the viewer),
    drawn back to front, Lambert-shaded, folded ones red, cropped to ``box`` (x0, y0, x1, y1)."""
    img = Image.new("RGB", (PANEL, PANEL), "white")
    draw = ImageDraw.Draw(img)
    p = deformed @ view.T
    x0, y0, x1, y1 = box
    scale = PANEL / max(x1 - x0, y1 - y0)
    screen = np.c_[(p[:, 0] - x0) * scale, PANEL - (p[:, 1] - y0) * scale]
    folded = folded_triangles(rest, deformed, triangles)
    n = np.cross(p[triangles[:, 1]] - p[triangles[:, 0]], p[triangles[:, 2]] - p[triangles[:, 0]])
    shade = np.abs(n @ np.array([0.3, 0.4, 0.87])) / np.maximum(np.linalg.norm(n, axis=1), 1e-12)
    for t in np.argsort(p[triangles, 2].mean(axis=1)):
        corners = [tuple(screen[i]) for i in triangles[t]]
        if folded[t]:
            draw.polygon(corners, fill=(220, 30, 30), outline=(120, 0, 0))
        elif wire:
            draw.polygon(corners, fill=(235, 235, 235), outline=(120, 120, 120))
        else:
            g = int(70 + 170 * shade[t])
            draw.polygon(corners, fill=(g, int(g * 0.85), int(g * 0.75)))
    return img


def figure(grid_mesh, grid_out, face, muscle: LinearMuscle, face_out) -> Image.Image:
    """Rows: modes; columns: the grid at each contraction, then the face crop at each contraction."""
    label_h, label_w = 24, 150
    cols = 2 * len(CONTRACTIONS)
    img = Image.new("RGB", (label_w + cols * PANEL, label_h + len(MODES) * PANEL), "white")
    draw = ImageDraw.Draw(img)
    front = np.eye(3)
    turn = np.radians(35.0)
    three_quarter = np.array([[np.cos(turn), 0, -np.sin(turn)], [0, 1, 0], [np.sin(turn), 0, np.cos(turn)]])
    face_box = _face_box(muscle, three_quarter)
    tri = skin_triangles(face)
    for j, c in enumerate(CONTRACTIONS):
        draw.text((label_w + j * PANEL + 8, 6), f"grid, c = {c}", fill="black")
        draw.text((label_w + (len(CONTRACTIONS) + j) * PANEL + 8, 6), f"face, c = {c}", fill="black")
    for i, mode in enumerate(MODES):
        draw.text((6, label_h + i * PANEL + PANEL // 2), mode, fill="black")
        for j, c in enumerate(CONTRACTIONS):
            g = draw_panel(grid_mesh[0], grid_out[mode][c], grid_mesh[1], front, (-0.55, -0.55, 0.55, 0.55), True)
            f = draw_panel(face.vertices, face_out[mode][c], tri, three_quarter, face_box, False)
            img.paste(g, (label_w + j * PANEL, label_h + i * PANEL))
            img.paste(f, (label_w + (len(CONTRACTIONS) + j) * PANEL, label_h + i * PANEL))
    return img


def _face_box(muscle: LinearMuscle, view: np.ndarray) -> tuple[float, float, float, float]:
    """A square around the muscle, in the view's screen coordinates."""
    centre = (muscle.fixed + muscle.insertion) / 2 @ view.T
    half = 0.4
    return centre[0] - half, centre[1] - half, centre[0] + half, centre[1] + half


def main() -> None:
    face = load_face()
    runtime = Runtime(face, dtype=np.float64)
    zygomatic = next(m for m in runtime.rig.muscles if m.name == FACE_MUSCLE)
    grid_mesh = flat_grid()
    grid_out = grid_cases()
    face_out = face_cases(runtime)
    rows = (table_rows("grid", grid_mesh[0], grid_mesh[1], GRID_MUSCLE, grid_out)
            + table_rows("face", face.vertices, skin_triangles(face), zygomatic, face_out))
    table = markdown_table(rows)
    every = every_muscle_table(face, runtime)
    times = timings(Runtime(face))  # the float32 runtime the live loop and the bench use
    time_table = _time_table(times)
    print(table, every, time_table, sep="\n\n")
    DOCS.mkdir(exist_ok=True)
    figure(grid_mesh, grid_out, face, zygomatic, face_out).save(DOCS / "muscle_experiment.png")
    (DOCS / "muscle_experiment.md").write_text(_report(table, every, time_table), encoding="utf-8")


def _time_table(times: list[tuple[str, str, float]]) -> str:
    """Markdown: one row per pose, one column per mode (ms per frame)."""
    modes = list(dict.fromkeys(m for _, m, _ in times))
    poses = list(dict.fromkeys(p for p, _, _ in times))
    ms = {(p, m): t for p, m, t in times}
    lines = ["| pose | " + " | ".join(f"{m} ms" for m in modes) + " |", "|---|" + "---:|" * len(modes)]
    lines += [f"| {p} | " + " | ".join(f"{ms[p, m]:.2f}" for m in modes) + " |" for p in poses]
    return "\n".join(lines)


def _report(table: str, every: str, time_table: str) -> str:
    doc = __doc__.split("\n\n", 1)[1].rsplit("\n\nWrites", 1)[0]
    return (f"# Muscle experiment (tools/checks/muscle_experiment.py)\n\n{doc}\n\n![deformed grids and face crops]"
            f"(muscle_experiment.png)\n\n{table}\n\n## Every default muscle alone: folded skin triangles\n\n"
            f"{every}\n\n## Per-frame cost on the default face (Runtime.deform_faps, median of 50)\n\n{time_table}\n")


if __name__ == "__main__":
    main()
