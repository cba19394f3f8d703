"""Generate a face's rig from its MPEG-4 feature points.

The rig is built by rules stated in terms of the feature points (FDP ids, ISO/IEC 14496-2
Annex C), so any face that has them gets a rig the same way; the default face's shipped rig is
the output of this module (``tools/builders/build_default_face.py`` writes it).

Regions (Zhang & Chen's functional regions), decided per skin vertex, first rule that matches:

* ``rest``: behind the face (z below the jaw angle 2.13), above the hairline band, below the neck
  line: neck, scalp, ears; still except for head rotation. The jaw band is taken out of it: the
  skin outside the face oval below the jaw angles' height, within ``JAW_BAND`` of the jaw line
  along the skin (under the chin, the throat's top, under the ears); it joins the regions below.
* ``upper_mouth`` / ``lower_mouth``: the mouth bag (the skin reached from the lips' meeting line
  without crossing it) split by distance along it to the line's two halves; the skin between the
  nose base and the meeting line (``_lip_line``: it rises to the corners), and between that line
  and the chin/throat, inside the nasolabial and chin lines.
* ``nose``: between the nasion and the nose base, inside a width growing from the nasal bone to
  the alae.
* ``forehead``: above the lower eyelids: brows, lids, glabella, forehead.
* ``cheek_l`` / ``cheek_r``: the rest of the front, split at the mid-line; it reaches down over the
  jaw line to the neck so that the jaw drags it smoothly.
* Parts other than the skin: an ``attached`` part (lashes, tear lines) takes the region of the
  skin vertex nearest to each of its vertices; a ``mouth`` part (socket, gums) splits at the
  meeting line.
* Parts: eyeballs rigid about their centres, lower teeth rigid with the jaw, the tongue rigid
  on the jaw (its own motion in the jaw's frame), upper teeth still. The four lids are rigid parts too, but of control points only: their margin points
  turn about the eyeball centre and the lid skin follows by DFFD (the paper's hybrid eyelids);
  toward the still eye corners a margin point turns less (``_lid_share``), so a closing or
  opening lid does not fold the skin at the corners.

Control points per region: the feature points the FAPs move (active, direct: on their vertex),
extra lid-margin points (the hybrid eyelids turn them about the eyeball centre), lip lines (the
lip FDPs are keys; points between them along the vermilion border and the lips' meeting line are
interpolated), and jaw-line points attached to the jaw. Borders decide the rest, along the mesh
edges between regions:

* where a region is *driven* by its neighbour (cheeks by both mouth regions, the nose by the upper
  mouth), its border vertices carry passive points, spaced about ``BORDER_SPACING`` apart,
  that follow the neighbour's DFFD: the jaw drags the cheeks and the border cannot fold or gape;
* where it drives its neighbour, its border is free (nothing pins the chin's sides while the jaw
  opens);
* elsewhere (the still neck and scalp, regions that meet without driving each other) the border
  vertices carry fixed anchors.

A few indirect anchors under the skin (off the surface, weight 0.5: softer) steady each region's
interior; under the lower mouth they ride on the jaw. Weights: 1 for points on the skin; the 8 box
corners weigh 0 (see ``puppet.runtime.dffd``).

The skin grid's points ride on the jaw by a share: all of it on the chin, fading up the cheeks to
the mouth corners, and over the jaw band fading from the jaw line down the throat and toward the
ears, so that the jaw's pull eases into the still neck with no seam or pinned row at the jaw line.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from puppet.face.default import default_face, load_default_rig
from puppet.face.landmarks import seam_pairs
from puppet.face.motiontransfer import transfer_motions
from puppet.face.muscles import default_muscles
from puppet.face.rig import ControlPoint, LipLine, Region, Rig, RigError, RigidPart, load_rig

INDIRECT_WEIGHT = 0.5
CORNER_JAW_SHARE = 0.5  # how far the lip corners go with the jaw
CHIN_FADE = 0.3  # the grid's jaw share is whole at least this far (of corner to chin height) below the corners
BORDER_SPACING = 0.12  # border point spacing, as a fraction of the eye separation
DRIVERS = {"cheek_l": ("upper_mouth", "lower_mouth"), "cheek_r": ("upper_mouth", "lower_mouth"),
           "nose": ("upper_mouth",)}
UNPINNED = {frozenset(("upper_mouth", "lower_mouth"))}  # the lips part; neither pins the other
DFFD_REGIONS = ("forehead", "nose", "upper_mouth", "lower_mouth", "cheek_l", "cheek_r")
BOX_SCALE = 1.5
BAG_FREE_DEPTH = 0.3  # mouth-bag skin this close to the lips' meeting line follows the lips only
BAG_SPACING = 0.12  # spacing of the mouth bag's anchors (fractions of the eye separation)
GRID_SPACING = {"forehead": 0.055, "nose": 0.055, "cheek_l": 0.055, "cheek_r": 0.055,
                "upper_mouth": 0.045, "lower_mouth": 0.045}  # as BORDER_SPACING
CORNER_EASE = 0.3  # beside the lip corners, over this share of the mouth's half-width the lower mouth's
# grid points ease from the jaw's whole motion to the cheek's share at their height
JAW_BAND = 1.2  # how far below and behind the jaw line the jaw's pull reaches (eye separations)
JAW_BAND_RISE = 0.5  # ... and how far below the jaw angles' height (fraction of angle to chin height)

# Lip lines: FDP keys in order along each contour, from the right corner to the left.
LIP_LINES = {
    "upper_outer": ("vermilion_border", ["8.4", "8.6", "8.9", "8.1", "8.10", "8.5", "8.3"]),
    "lower_outer": ("vermilion_border", ["8.4", "8.8", "8.2", "8.7", "8.3"]),
    "upper_inner": ("mouth_opening", ["2.5", "2.7", "2.2", "2.6", "2.4"]),
    "lower_inner": ("mouth_opening", ["2.5", "2.9", "2.3", "2.8", "2.4"]),
}
FOREHEAD_ACTIVE = ["4.1", "4.2", "4.3", "4.4", "4.5", "4.6", "3.1", "3.2", "3.3", "3.4", "3.13", "3.14"]
FOREHEAD_FIXED = ["3.7", "3.8", "3.11", "3.12", "3.9", "3.10", "11.1", "11.2", "11.3"]
NOSE_ACTIVE = ["9.1", "9.2", "9.3"]
NOSE_FIXED = ["9.6", "9.7", "9.12", "9.13", "9.14"]
LOWER_JAW = ["8.2", "8.7", "8.8", "2.3", "2.8", "2.9", "2.10", "2.1", "2.11", "2.12"]
UPPER_ACTIVE = ["8.1", "8.5", "8.6", "8.9", "8.10", "2.2", "2.6", "2.7"]
CORNERS = ["8.3", "8.4", "2.4", "2.5"]
REQUIRED = sorted(set(FOREHEAD_ACTIVE + FOREHEAD_FIXED + NOSE_ACTIVE + NOSE_FIXED
                      + LOWER_JAW + UPPER_ACTIVE + CORNERS
                      + ["2.13", "2.14", "5.1", "5.2", "5.3", "5.4", "3.5", "3.6", "7.1", "9.15"]))


def rig_for_face(face) -> Rig:
    """The rig saved beside a face folder's mesh (``face.rig_file``) when it was made for this mesh
    (a folder's own rig wins: ``puppet calibrate-face`` writes the default face's mesh with a rig
    of its own), else the shipped rig when ``face`` is the default face (same mesh hash), else a
    rig generated from the face's feature points."""
    saved = getattr(face, "rig_file", None)
    for rig in (load_rig(saved) if saved is not None else None, load_default_rig()):
        if rig is not None and rig.face_hash == face.content_hash:
            return rig
    return build_rig(face)


def build_rig(face, *, grid: bool = True, calibrated: bool = True) -> Rig:
    """Build the rig of a face with feature points, parts and contours (see module docstring).

    ``grid=False`` leaves out the skin grid: the coarse layout of feature points, lines and
    borders only (what FAPs move by definition; the calibration starts from how it moves).
    ``calibrated`` gives the grid the default face's calibrated FAP motions, carried over by
    ``puppet.face.motiontransfer``."""
    missing = [f for f in REQUIRED if f not in face.feature_points]
    if missing:
        raise RigError(f"face {face.name!r}: cannot rig without feature points {missing}")
    rig = _Builder(face, grid).build()
    rig.muscles = default_muscles(face)  # Waters' muscles, placed by the feature points (puppet.face.muscles)
    rig.face_hash = face.content_hash    # the mesh it was made for: a saved rig is only reused on it
    if grid and calibrated:
        rig.fap_motions = _default_motions(face, rig)
        rig.fap_follow = _default_follow()
    return rig


def _depth(fp: dict[str, np.ndarray]) -> float:
    """How far the nose tip stands in front of the jaw angles, in spans of the outer eye corners."""
    return float((fp["9.3"][2] - (fp["2.13"][2] + fp["2.14"][2]) / 2) / (fp["3.7"][0] - fp["3.12"][0]))


def _default_follow() -> dict[tuple[int, int], tuple[float, float]]:
    """The shipped default rig's follow ranges of the inner and outer lip FAPs
    (``puppet.runtime.foldlimits``), in FAPU: the inner and outer lip points lie a few millimetres apart
    on every face."""
    default = load_default_rig()
    return dict(default.fap_follow) if default is not None else {}


def _default_motions(face, rig: Rig) -> dict[int, dict[str, np.ndarray]]:
    """The shipped default rig's FAP motions, carried over to ``rig`` (none if it has none)."""
    default = load_default_rig()
    if default is None or not default.fap_motions:
        return {}
    return transfer_motions(default, default_face(), rig, face)


class _Builder:
    def __init__(self, face, grid: bool = True) -> None:
        self.face = face
        self.grid = grid
        self.v = np.array(face.vertices, dtype=float)
        self.fp = {k: np.array(p, dtype=float) for k, p in face.feature_points.items()}
        self.fv = dict(face.feature_vertices)
        self.points: list[ControlPoint] = []
        self._named: set[str] = set()  # the points' names: ``_add`` asks thousands of times on a grid
        self.region_of = np.full(len(self.v), "", dtype=object)
        self.edges = _welded_edges(face)

    # -- regions ------------------------------------------------------------------------

    def build(self) -> Rig:
        self._segment()
        regions = self._regions_with_points()
        rig = Rig(
            n_vertices=len(self.v),
            control_points=self.points,
            regions=regions,
            rigid_parts=self._rigid_parts(),
            lip_lines=self.lip_lines,
            box_scale=BOX_SCALE,
        )
        rig.validate()
        return rig

    def _segment(self) -> None:
        fp, v = self.fp, self.v
        skin = self.face.parts["skin"]
        x, y, z = v[skin, 0], v[skin, 1], v[skin, 2]
        ax = np.abs(x)
        lip_y = (fp["2.2"][1] + fp["2.3"][1]) / 2
        nose_base = fp["9.15"][1]
        nasion = fp["9.7"][1]
        chin = fp["2.1"][1]
        neck_y = chin - 0.5 * (fp["9.15"][1] - chin)
        hair_y = fp["11.1"][1] + 0.3 * (fp["11.1"][1] - fp["4.3"][1])
        lid_y = fp["3.9"][1] - 0.25 * (fp["3.3"][1] - fp["3.9"][1])
        mouth_w = fp["8.3"][0]
        z_front = fp["2.13"][2]

        label = np.full(len(skin), "rest", dtype=object)
        self.jaw_share = self._jaw_band_share()
        self.in_jaw_band = np.isfinite(self.jaw_share)
        front = ((z > z_front) & (y > neck_y) & (y < hair_y)) | self.in_jaw_band[skin]
        label[front & (x >= 0)] = "cheek_l"
        label[front & (x < 0)] = "cheek_r"
        label[front & (y >= lid_y)] = "forehead"
        t = np.clip((y - nose_base) / (nasion - nose_base), 0, 1)
        nose_w = (1 - t) * 1.25 * fp["9.1"][0] + t * 1.3 * fp["9.7"][0]
        label[front & (y >= nose_base) & (y < nasion) & (ax < nose_w)] = "nose"
        s = np.clip((nose_base - y) / (nose_base - lip_y), 0, 1)
        # The nasolabial lines diverge downward: at the nose base the upper mouth is no wider than
        # the mouth, even when the nostril points sit wide (else a box cut through the cheeks
        # that the lips' motion lifts as a block: a raised rectangle on smiling).
        upper_w = (1 - s) * min(1.25 * fp["9.1"][0], mouth_w) + s * 1.3 * mouth_w
        above = y >= self._lip_line(x)
        label[front & (y < nose_base) & above & (ax < upper_w)] = "upper_mouth"
        r = np.clip((lip_y - y) / (lip_y - chin), 0, 1)
        lower_w = (1 - r) * 1.3 * mouth_w + r * 1.2 * fp["2.11"][0]
        label[front & ~above & (ax < lower_w)] = "lower_mouth"
        bag = self._mouth_bag(skin)
        self.bag = skin[bag]
        label[bag] = np.where(self._bag_upper(self.bag), "upper_mouth", "lower_mouth")
        self._check_regions(label)
        self.region_of[skin] = label
        for part, region in (("eye_l", "eyeball_l"), ("eye_r", "eyeball_r"), ("teeth_upper", "upper_teeth"),
                             ("teeth_lower", "lower_teeth"), ("tongue", "tongue")):
            if part in self.face.parts:
                self.region_of[self.face.parts[part]] = region
        if "mouth" in self.face.parts:
            m = self.face.parts["mouth"]
            self.region_of[m] = np.where(v[m, 1] >= self._lip_line(v[m, 0]), "upper_mouth", "lower_mouth")
        if "attached" in self.face.parts:  # lashes, tear lines...: they follow the skin under them
            a = self.face.parts["attached"]
            gap, nearest = cKDTree(v[skin]).query(v[a])
            self.region_of[a] = np.where(self._far_pieces(a, gap), "rest", label[nearest])

    def _check_regions(self, label: np.ndarray) -> None:
        """A RigError naming the DFFD regions that got no skin: a face's regions are the skin in
        front of its jaw angles (2.13, 2.14), so a face flattened to a relief or a plane has none,
        and its building would end in a traceback."""
        empty = [r for r in DFFD_REGIONS if not np.any(label == r)]
        if empty:
            raise RigError(f"face {self.face.name!r}: no skin for the {', '.join(empty)} region"
                           f"{'s' if len(empty) > 1 else ''}: a face's regions are the skin in front of its jaw "
                           f"angles (feature points 2.13, 2.14), and its nose tip stands {_depth(self.fp):.2f} "
                           f"outer-eye-corner spans in front of them (the default face's: "
                           f"{_depth(default_face().feature_points):.2f}); a flat face cannot be rigged: give it "
                           "depth, or give 2.13 and 2.14 at the jaw's back corners")

    def _far_pieces(self, members: np.ndarray, gap: np.ndarray) -> np.ndarray:
        """Per vertex of ``members``, whether its connected piece reaches farther than
        ``ATTACHED_REACH`` from the skin anywhere (``gap``: each vertex's distance): not a lash but a
        body, a hat, hair, which stay with the head. A whole figure's body box riding the cheeks by
        two corners stretched its sides and capped the jaw's opening at a twentieth."""
        inside = np.zeros(len(self.v), dtype=bool)
        inside[members] = True
        e = self.edges[inside[self.edges].all(axis=1)]
        n = len(self.v)
        piece = connected_components(sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)),
                                     directed=False)[1][members]
        reach = np.zeros(piece.max() + 1)
        np.maximum.at(reach, piece, gap)
        return reach[piece] > self._scale(ATTACHED_REACH)

    def _lip_line(self, x: np.ndarray) -> np.ndarray:
        """The height of the lips' meeting line at each x, which splits the skin between the two
        mouth regions: midway between the halves of the mouth-opening loop (2.5 to 2.4 through 2.2,
        and through 2.3), level with the corners beyond them; without the loop, level with the
        middle of 2.2 and 2.3. The line rises to the corners: split at the mid-line's height, the
        lower lip's inner edge beside the corners went with the upper lip and, as the jaw opened,
        held the lip corner up as a web across the opened mouth."""
        halves = self._lip_halves()
        if halves is None:
            return np.full(np.shape(x), (self.fp["2.2"][1] + self.fp["2.3"][1]) / 2)
        heights = []
        for half in halves:
            p = self.v[half]
            order = np.argsort(p[:, 0])
            heights.append(np.interp(x, p[order, 0], p[order, 1]))
        return (heights[0] + heights[1]) / 2

    def _lip_halves(self) -> list[list[int]] | None:
        """The mouth-opening loop's two halves, each from corner 2.5 to corner 2.4, through 2.2
        (upper) and through 2.3 (lower); None when the face has no such loop."""
        loop = list(np.asarray(self.face.contours.get("mouth_opening", [])))
        if not all(self.fv.get(k) in loop for k in ("2.2", "2.3", "2.4", "2.5")):
            return None
        a, b = loop.index(self.fv["2.5"]), loop.index(self.fv["2.4"])
        return [_loop_path_via(loop, a, b, self.fv[mid]) for mid in ("2.2", "2.3")]

    def _jaw_band_share(self) -> np.ndarray:
        """How much of the jaw's motion each skin vertex below and behind the jaw line takes (NaN
        off that band): all of it on the jaw line (the face oval's arc below the jaw angles), easing
        to none ``JAW_BAND`` away along the skin outside the oval (down the throat, back under the
        ears) and toward the jaw angles' height (``JAW_BAND_RISE``). An opening or shifting jaw
        then stretches the skin under the chin smoothly into the still neck, as the submandibular
        skin does, instead of folding it against a seam where jaw-carried skin meets the neck."""
        n = len(self.v)
        share = np.full(n, np.nan)
        if "face_oval" not in self.face.contours:
            return share
        oval = np.asarray(self.face.contours["face_oval"])
        skin = np.zeros(n, dtype=bool)
        skin[self.face.parts["skin"]] = True
        on_oval = np.zeros(n, dtype=bool)
        on_oval[oval] = True
        edges = self.edges
        edges = edges[skin[edges].all(axis=1)]
        cut = edges[~on_oval[edges].any(axis=1)]
        _, comp = connected_components(sp.coo_matrix((np.ones(len(cut)), (cut[:, 0], cut[:, 1])), shape=(n, n)),
                                       directed=False)
        nose = np.flatnonzero(skin)[np.argmin(np.linalg.norm(self.v[skin] - self.fp["9.3"], axis=1))]
        outside = skin & ~on_oval & (comp != comp[nose])
        e = edges[(outside | on_oval)[edges].all(axis=1)]
        length = np.linalg.norm(self.v[e[:, 0]] - self.v[e[:, 1]], axis=1)
        graph = sp.coo_matrix((length, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
        angle_y = (self.fp["2.13"][1] + self.fp["2.14"][1]) / 2
        d = dijkstra(graph, directed=False, min_only=True, indices=oval[self.v[oval, 1] <= angle_y])
        y = self.v[:, 1]
        rise = JAW_BAND_RISE * (angle_y - self.fp["2.1"][1])
        fade = _smoothstep(1 - d / self._scale(JAW_BAND)) * _smoothstep((angle_y - y) / rise)
        band = outside & (d < self._scale(JAW_BAND)) & (y < angle_y)
        share[band] = fade[band]
        return share

    def _mouth_bag(self, skin: np.ndarray) -> np.ndarray:
        """Skin vertices reachable from inside the mouth without crossing the lips' meeting line."""
        loop = np.asarray(self.face.contours["mouth_opening"])
        n = len(self.v)
        blocked = np.zeros(n, dtype=bool)
        blocked[loop] = True
        on_skin = np.zeros(n, dtype=bool)
        on_skin[skin] = True
        edges = self.edges
        keep = on_skin[edges].all(axis=1) & ~blocked[edges].any(axis=1)
        e = edges[keep]
        graph = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        _, comp = connected_components(graph, directed=False)
        outside = comp[self.fv["11.4"]] if "11.4" in self.fv else comp[self.fv["9.3"]]
        return (comp[skin] != outside) & ~blocked[skin]

    def _bag_upper(self, bag: np.ndarray) -> np.ndarray:
        """Which mouth-bag vertices go with the upper lip: those nearer, along the bag's edges,
        to the upper half of the lips' meeting line than to its lower half. Behind closed lips
        the bag starts as a flat tube at the lips' height, so height alone does not split it:
        its lower rim would hang from the upper lip and curtain the opened mouth. Where the
        lips are one sheet of skin (``_closed_mouth``), the whole bag goes with the upper lip."""
        if self._closed_mouth(bag):
            return np.ones(len(bag), dtype=bool)
        halves = self._lip_halves()
        inside = np.zeros(len(self.v), dtype=bool)
        inside[bag] = inside[np.concatenate(halves)] = True
        e = self.edges
        e = e[inside[e].all(axis=1)]
        w = np.linalg.norm(self.v[e[:, 0]] - self.v[e[:, 1]], axis=1)
        graph = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(self.v),) * 2).tocsr()
        d_up, d_lo = (dijkstra(graph, directed=False, min_only=True, indices=half[1:-1]) for half in halves)
        return d_up[bag] <= d_lo[bag]

    def _closed_mouth(self, bag: np.ndarray) -> bool:
        """Whether the lips are one sheet of skin (a scan with a closed mouth, no cavity behind
        them): no ``bag`` vertex lies farther than ``BAG_FREE_DEPTH`` from the lips' meeting line.
        Such a bag is no more than the row where the lips join, left between the meeting line's
        halves where the landmarks put them a row above and below it; split by distance to the
        halves, its vertices went alternately with the upper and the lower lip, and the parted
        lips' edge zigzagged. A mouth with a cavity reaches several times that deep."""
        opening = self.v[np.asarray(self.face.contours["mouth_opening"])]
        return bool(np.all(cKDTree(opening).query(self.v[bag])[0] <= self._scale(BAG_FREE_DEPTH)))

    def _regions_with_points(self) -> list[Region]:
        self.members: dict[str, list[str]] = {}
        self.lip_lines: list[LipLine] = []
        self._forehead()
        self._nose()
        self._mouth()
        self._cheeks()
        self._borders()
        if self.grid:
            self._skin_grid()
        regions = []
        for name in DFFD_REGIONS:
            verts = np.flatnonzero(self.region_of == name).astype(np.int32)
            regions.append(Region(name, "dffd", verts, self.members[name]))
        for name, part in (("eyeball_l", "eye_l"), ("eyeball_r", "eye_r"),
                           ("lower_teeth", "jaw"), ("tongue", "tongue")):
            verts = np.flatnonzero(self.region_of == name).astype(np.int32)
            if len(verts):
                regions.append(Region(name, "rigid", verts, part=part))
        for name in ("upper_teeth", "rest"):
            verts = np.flatnonzero(self.region_of == name).astype(np.int32)
            if len(verts):
                regions.append(Region(name, "still", verts))
        return regions

    # -- control points -------------------------------------------------------------------

    def _add(self, region: str, name: str, role: str, *, vertex: int | None = None,
             position: np.ndarray | None = None, **kw) -> str:
        if name not in self._named:
            if position is None:
                position = self.v[vertex]
            weight = INDIRECT_WEIGHT if vertex is None else 1.0
            self.points.append(ControlPoint(name, np.asarray(position, float), role, weight, vertex, **kw))
            self._named.add(name)
        self.members.setdefault(region, [])
        if name not in self.members[region]:
            self.members[region].append(name)
        return name

    def _fdp(self, region: str, fdp: str, role: str, **kw) -> str:
        if fdp in self.fv:
            return self._add(region, fdp, role, vertex=int(self.fv[fdp]), **kw)
        return self._add(region, fdp, role, position=self.fp[fdp], **kw)

    def _nearest(self, region: str, xyz: np.ndarray) -> int:
        verts = np.flatnonzero(self.region_of == region)
        return int(verts[np.argmin(np.linalg.norm(self.v[verts] - xyz, axis=1))])

    def _borders(self) -> None:
        """Passive points, fixed anchors or nothing on each border (see module docstring)."""
        edges = self.edges
        region = self.region_of
        spacing = self._scale(BORDER_SPACING)
        for name in DFFD_REGIONS:
            for side in (0, 1):
                mine = edges[(region[edges[:, side]] == name) & (region[edges[:, 1 - side]] != name)]
                for other in sorted(set(region[mine[:, 1 - side]])):
                    if name in DRIVERS.get(other, ()) or frozenset((name, other)) in UNPINNED:
                        continue
                    verts = np.unique(mine[region[mine[:, 1 - side]] == other, side])
                    self._border_points(name, other, verts, spacing)

    def _border_points(self, name: str, other: str, verts: np.ndarray, spacing: float) -> None:
        driven = other in DRIVERS.get(name, ())
        positions = {p.name: p.position for p in self.points}
        taken = [positions[n] for n in self.members.get(name, [])]
        for vertex in _spread_out(self.v, verts, taken, spacing):
            if driven:
                self._add(name, f"{name}_from_{other}_{vertex}", "passive", vertex=int(vertex), driver=other)
            else:
                role = "active" if other in DFFD_REGIONS else "fixed"  # skin on both sides: calibratable
                self._add(name, f"{name}_edge_{vertex}", role, vertex=int(vertex))

    def _skin_grid(self) -> None:
        """Active points spread over each region's front skin, ``GRID_SPACING`` apart: the
        capacity the skin needs between the feature points (brows, lids, nasolabial fold, cheeks,
        chin). No FAP moves them until a calibration (``puppet.runtime.fapcalibration``) says how; until
        then they hold the skin like anchors. Under the mouth corners they ride on the jaw, fully
        on the chin and fading out up the cheeks, so an opening jaw stretches the cheek evenly;
        beside the corners the lower mouth's ease into the cheeks' share (``CORNER_EASE``): at the
        corners' height, taken fully, they dropped past the cheek skin below them and folded it;
        below and behind the jaw line they take the jaw band's share (``_jaw_band_share``), fading
        down the throat into the still neck. The share is whole from midway between the jaw angles'
        and the chin's heights down, or from ``CHIN_FADE`` of the way from the corners to the chin
        where that is lower: jaw angles placed high (ICT's sit level with the ear lobes, above the
        mouth) put the midway above the corners, and the fade turned over, carried the whole face
        above them on the jaw: an opened jaw dragged the forehead (ridges in surprise)."""
        skin = np.zeros(len(self.v), dtype=bool)
        skin[self.face.parts["skin"]] = True
        skin[self.face.parts["skin"][self._mouth_bag(self.face.parts["skin"])]] = False
        positions = {p.name: p.position for p in self.points}
        corner_y = self.fp["8.3"][1]
        chin_y = self.fp["2.1"][1]
        jaw_y = min((self.fp["2.13"][1] + chin_y) / 2, corner_y - CHIN_FADE * (corner_y - chin_y))
        up_cheek = np.clip((corner_y - self.v[:, 1]) / (corner_y - jaw_y), 0, 1)
        beside = np.clip((np.abs(self.v[:, 0]) / self.fp["8.3"][0] - 1) / CORNER_EASE, 0, 1)
        for region, spacing in GRID_SPACING.items():
            verts = np.flatnonzero((self.region_of == region) & skin)
            taken = [positions[n] for n in self.members.get(region, [])]
            on_face = (1 - beside) + beside * up_cheek if region == "lower_mouth" else up_cheek
            shares = np.where(self.in_jaw_band, self.jaw_share, on_face)
            for vertex in _spread_out(self.v, verts, taken, self._scale(spacing)):
                share = float(shares[vertex])
                carried = {"attach": "jaw", "attach_weight": max(share, 0.05)} if share > 0 else {}
                self._add(region, f"{region}_grid_{vertex}", "active", vertex=int(vertex), **carried)

    def _lip_taper(self, xyz: np.ndarray) -> np.ndarray:
        """The jaw's share of a lower-lip feature point at ``xyz`` (..., 3): whole on the mid-line,
        falling linearly across the lip to the corners' own share (``CORNER_JAW_SHARE``) at their
        width, as the lip drops in the artist's jawOpen (its sides three quarters as far as its
        middle); whole again from the lower lip's outer edge (8.2) down to the chin (2.1). Carried
        whole right up to the corners, the lip's sides dropped as far as its middle, and the fit of
        every open mouth pulled the middle down past them into a V. The skin grid around keeps
        its whole share: its calibrated motions follow the lip (tapered too, they pulled the grid
        beside the inner lip's corners back past the lip's edge, folding it from open_jaw 750)."""
        across = np.clip(np.abs(xyz[..., 0]) / abs(self.fp["8.3"][0]), 0, 1)
        lip_y, chin_y = self.fp["8.2"][1], self.fp["2.1"][1]
        on_lip = np.clip((xyz[..., 1] - chin_y) / (lip_y - chin_y), 0, 1)
        return 1 - (1 - CORNER_JAW_SHARE) * across * on_lip

    def _midline_anchors(self, region: str) -> None:
        """Fixed anchors down the mid-line, so one side's motion does not leak to the other."""
        verts = np.flatnonzero(self.region_of == region)
        width = np.ptp(self.v[verts, 0])
        middle = verts[np.abs(self.v[verts, 0]) < 1e-3 * width]
        positions = {p.name: p.position for p in self.points}
        taken = [positions[n] for n in self.members.get(region, [])]
        for vertex in _spread_out(self.v, middle, taken, self._scale(BORDER_SPACING)):
            self._add(region, f"{region}_midline_{vertex}", "active", vertex=vertex)

    def _deep_anchors(self, region: str, prefix: str, depth: float, attach: str | None = None) -> None:
        """Indirect fixed anchors under the region's skin (its centre pushed back along -z),
        carried by a rigid part if one is named. The jaw band is left out of the centre: the
        anchors steady the face, not the throat."""
        verts = np.flatnonzero((self.region_of == region) & ~self.in_jaw_band)
        p = self.v[verts]
        lo, hi = p.min(axis=0), p.max(axis=0)
        for i, fx in enumerate((0.25, 0.75)):
            xyz = np.array([lo[0] + fx * (hi[0] - lo[0]), (lo[1] + hi[1]) / 2, lo[2] - depth])
            self._add(region, f"{prefix}{i}", "fixed", position=xyz, attach=attach)

    def _forehead(self) -> None:
        for f in FOREHEAD_ACTIVE:
            lid = _lid_group(f)
            self._fdp("forehead", f, "active", group=lid, attach=lid)
        for f in FOREHEAD_FIXED:
            self._fdp("forehead", f, "fixed")
        self._lid_margins()
        self._midline_anchors("forehead")
        self._deep_anchors("forehead", "forehead_deep_", self._scale(0.25))

    def _lid_margins(self) -> None:
        """Every vertex of each lid margin (the lid-opening loop between the eye corners) rides on
        its lid, so a closing lid keeps a smooth edge. Toward the eye corners, which stay put, a
        margin point goes less far with its lid (``_lid_share``): a margin vertex a hair's breadth
        from a still corner, turned the whole way, folds the skin between them (an upper lid
        folded there at 149 IRISD, a lower lid at 100, and every smile's raised lower lids)."""
        for side, loop_name, corners in (("l", "left_lid_opening", ("3.7", "3.11")),
                                         ("r", "right_lid_opening", ("3.12", "3.8"))):
            loop = list(np.asarray(self.face.contours[loop_name]))
            a, b = (loop.index(self.fv[c]) for c in corners)
            for lid, centre in (("upper", self.fv["3.1" if side == "l" else "3.2"]),
                                ("lower", self.fv["3.3" if side == "l" else "3.4"])):
                path = _loop_path_via(loop, a, b, centre)
                for vertex, share in zip(path[1:-1], _lid_share(self.v[path])[1:-1]):
                    if vertex != centre:
                        self._add("forehead", f"{lid}_lid_{side}_{vertex}", "active", vertex=int(vertex),
                                  group=f"{lid}_lid_{side}", attach=f"{lid}_lid_{side}",
                                  attach_weight=float(share))

    def _nose(self) -> None:
        for f in NOSE_ACTIVE:
            self._fdp("nose", f, "active")
        for f in NOSE_FIXED:
            self._fdp("nose", f, "fixed")
        self._deep_anchors("nose", "nose_deep_", self._scale(0.2))

    def _mouth(self) -> None:
        for f in UPPER_ACTIVE:
            self._fdp("upper_mouth", f, "active")
        for f in CORNERS:
            self._fdp("upper_mouth", f, "active", attach="jaw", attach_weight=CORNER_JAW_SHARE)
            self._fdp("lower_mouth", f, "active")
        for f in LOWER_JAW:
            self._fdp("lower_mouth", f, "active", attach="jaw", attach_weight=float(self._lip_taper(self.fp[f])))
        for name, (contour, keys) in LIP_LINES.items():
            region = "upper_mouth" if name.startswith("upper") else "lower_mouth"
            points = self._lip_points(name, contour, keys, region)
            self.lip_lines.append(LipLine(name, keys, points))
        self._deep_anchors("upper_mouth", "upper_mouth_deep_", self._scale(0.35))
        self._deep_anchors("lower_mouth", "lower_mouth_deep_", self._scale(0.35), attach="jaw")
        self._mouth_bag_anchors()

    def _mouth_bag_anchors(self) -> None:
        """Fixed points on the mouth bag away from the lips: on the lower half they ride on the
        jaw, on the upper half they stay. Without them DFFD extrapolates the deep bag from the
        lip points alone, and an opening jaw rolls the bag's floor forward out of the mouth
        instead of carrying it down with the teeth and tongue. Above the jaw's hinge the lower
        half's share of the jaw fades to nothing at its top, where it meets the still upper half:
        there the jaw's turn swings the back wall up and forward, into the upper half (it folded
        the bag's back wall with the jaw wide open)."""
        opening = self.v[np.asarray(self.face.contours["mouth_opening"])]
        bag = self.bag[cKDTree(opening).query(self.v[self.bag])[0] > self._scale(BAG_FREE_DEPTH)]
        spacing = self._scale(BAG_SPACING)
        share = self._lower_bag_share()
        for region in ("upper_mouth", "lower_mouth"):
            verts = bag[self.region_of[bag] == region]
            positions = {p.name: p.position for p in self.points}
            taken = [positions[n] for n in self.members.get(region, [])]
            for vertex in _spread_out(self.v, verts, taken, spacing):
                carried = {"attach": "jaw", "attach_weight": float(share[vertex])} \
                    if region == "lower_mouth" and share[vertex] > 0 else {}
                self._add(region, f"{region}_bag_{vertex}", "fixed", vertex=int(vertex), **carried)

    def _lower_bag_share(self) -> np.ndarray:
        """Per vertex, the jaw's share for a lower mouth-bag anchor there: 1 up to the jaw hinge's
        height, fading to 0 at the top of the lower half of the bag."""
        lower = self.bag[self.region_of[self.bag] == "lower_mouth"]
        if not len(lower):
            return np.ones(len(self.v))
        hinge, top = self._jaw_hinge()[1], self.v[lower, 1].max()
        return np.clip((top - self.v[:, 1]) / max(top - hinge, 1e-12), 0, 1)

    def _lip_points(self, name: str, contour: str, keys: list[str], region: str) -> list[str]:
        """One interpolated point on the contour midway between each pair of consecutive keys."""
        loop = list(np.asarray(self.face.contours[contour]))
        pos = {k: loop.index(self.fv[k]) for k in keys}
        points = []
        for a, b in zip(keys[:-1], keys[1:]):
            i, j = pos[a], pos[b]
            path = _loop_path(loop, i, j)
            if len(path) < 3:
                continue
            vertex = int(path[len(path) // 2])
            points.append(self._add(region, f"{name}_{a}_{b}", "interpolated", vertex=vertex))
        return points

    def _cheeks(self) -> None:
        for side, cheek, bone, angle, chin_corner in (("l", "5.1", "5.3", "2.13", "2.11"),
                                                       ("r", "5.2", "5.4", "2.14", "2.12")):
            region = f"cheek_{side}"
            self._fdp(region, cheek, "active")
            self._fdp(region, bone, "active")
            self._fdp(region, angle, "active", attach="jaw")
            for i, f in enumerate((1 / 3, 2 / 3)):
                xyz = (1 - f) * self.fp[chin_corner] + f * self.fp[angle]
                self._add(region, f"jaw_line_{side}{i}", "active", vertex=self._nearest(region, xyz), attach="jaw")
            self._deep_anchors(region, f"{region}_deep_", self._scale(0.3))

    def _scale(self, f: float) -> float:
        """A length as a fraction of the eye separation (the face's own scale)."""
        return f * abs(self.fp["3.5"][0] - self.fp["3.6"][0])

    def _jaw_hinge(self) -> np.ndarray:
        """Where the jaw turns when the mouth opens: on the mid-plane, at the lips' height, as far
        back as the jaw angles (2.13/2.14).

        The mandible opens by turning while its condyles glide forward; the centre of that combined
        motion lies near the middle of the ramus, about level with the bite, not at the condyle.
        Turning about it takes the chin mostly down and a little back, as a jaw does; a hinge up at
        the condyle (MakeHuman's joint-mouth marker, the face's ``pivots["jaw"]``) swings the chin
        back as much as down.
        """
        lip_y = (self.fp["2.2"][1] + self.fp["2.3"][1]) / 2
        back = (self.fp["2.13"][2] + self.fp["2.14"][2]) / 2
        return np.array([0.0, lip_y, back])

    def _rigid_parts(self) -> dict[str, RigidPart]:
        pivots = self.face.pivots
        skin = self.v[self.face.parts["skin"]]
        cut = self.face.contours.get("neck_cut")
        chin = self.fp["2.1"][1]
        below_chin = min(skin[:, 1].min(), chin - 0.5 * (self.fp["9.15"][1] - chin))  # a mask ends at the chin
        neck_lo = self.v[cut, 1].max() if cut is not None else below_chin
        neck = (float(neck_lo), float(chin))
        return {
            "head": RigidPart("head", self.fp["7.1"], neck=neck),
            "jaw": RigidPart("jaw", self._jaw_hinge(), axis=np.asarray(pivots.get("jaw_axis", (1.0, 0.0, 0.0)), float)),
            "eye_l": RigidPart("eye_l", np.asarray(pivots["eye_l"], float)),
            "eye_r": RigidPart("eye_r", np.asarray(pivots["eye_r"], float)),
            "tongue": RigidPart("tongue", self.fp.get("6.2", self._jaw_hinge()).copy(), parent="jaw"),
            **{f"{lid}_lid_{side}": RigidPart(f"{lid}_lid_{side}", np.asarray(pivots[f"eye_{side}"], float),
                                               axis=np.array([1.0, 0.0, 0.0]))
               for lid in ("upper", "lower") for side in ("l", "r")},
        }


def _lid_group(fdp: str) -> str | None:
    return {"3.1": "upper_lid_l", "3.2": "upper_lid_r", "3.3": "lower_lid_l", "3.4": "lower_lid_r"}.get(fdp)


def _welded_edges(face) -> np.ndarray:
    """Every triangle's edges (a, b), and each vertex an exporter split along a uv seam joined to
    its twin: the skin's connectivity by position (the mouth bag, the jaw band), else a skin split
    at the mid-line is two halves and the mouth bag took the far one for the mouth's inside."""
    tri = np.asarray(face.triangles)
    return np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]], seam_pairs(face)])


def _loop_path_via(loop: list[int], i: int, j: int, via: int) -> list[int]:
    """The vertices from loop[i] to loop[j] along the closed loop, the way that passes ``via``."""
    n = len(loop)
    forward = [loop[(i + k) % n] for k in range((j - i) % n + 1)]
    return forward if via in forward else [loop[(i - k) % n] for k in range((i - j) % n + 1)]


ATTACHED_REACH = 0.5  # eye separations: an attached piece farther than this from the skin stays with the head
LID_TAPER = 0.25  # the share of a lid margin, from each eye corner, over which its points ease in


def _lid_share(path: np.ndarray) -> np.ndarray:
    """How far each point of a lid margin path (corner to corner, positions) turns with its lid:
    0 at the still corners, rising linearly over ``LID_TAPER`` of the margin's length, then 1."""
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    t = length / length[-1]
    return np.minimum(1.0, np.minimum(t, 1 - t) / LID_TAPER)


def _loop_path(loop: list[int], i: int, j: int) -> list[int]:
    """The vertices from loop[i] to loop[j] the shorter way round the closed loop."""
    n = len(loop)
    forward = [loop[(i + k) % n] for k in range((j - i) % n + 1)]
    backward = [loop[(i - k) % n] for k in range((i - j) % n + 1)]
    return forward if len(forward) <= len(backward) else backward


def _smoothstep(t: np.ndarray) -> np.ndarray:
    """0 below 0, 1 above 1, easing in between with zero slope at both ends (no kink)."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _spread_out(v: np.ndarray, candidates: np.ndarray, taken: list[np.ndarray], spacing: float) -> list[int]:
    """Greedily pick candidate vertices, in order, at least ``spacing`` from each other and from
    ``taken``: each pick rules out the candidates after it that lie closer (those near it found
    in a k-d tree)."""
    p = v[np.asarray(candidates, dtype=np.int64)]
    free = np.ones(len(p), dtype=bool)
    if len(taken):
        free &= (np.linalg.norm(p[:, None] - np.asarray(taken)[None], axis=2) >= spacing).all(axis=1)
    tree = cKDTree(p) if len(p) else None
    chosen: list[int] = []
    for i in range(len(p)):
        if free[i]:
            chosen.append(int(candidates[i]))
            near = np.asarray(tree.query_ball_point(p[i], spacing * (1 + 1e-9)), dtype=np.int64)
            near = near[near > i]
            free[near[np.linalg.norm(p[near] - p[i], axis=1) < spacing]] = False
    return chosen
