"""MPEG-4 FAPs drive the rig, and a deformed mesh is measured back into FAPs.

``FapEngine.controls(values)`` turns one frame of the 68 FAP values (FAPU units, as in a .fap
file; index 0 = FAP 1) into the runtime's inputs: control point displacements and rigid motions.

* Translations (every FAP whose unit is a distance and whose feature point is an active control
  point of the rig): the point moves by value x FAPU along the FAP's positive direction. They are
  one small dense product.
* Calibrated motions (the rig's ``fap_motions``, ``puppet.runtime.fapcalibration``): every FAP, rigid ones
  included, also moves the skin grid's points as the example shapes showed, value x FAPU x the
  stored motion; they join the same product. A FAP's own feature point still moves by exactly
  value x FAPU: the grid holds none of them, so the encoder reads every FAP off its own point.
* open_jaw (3) turns the jaw about its hinge so that 2.1 drops by exactly value x MNS;
  thrust_jaw (14) and shift_jaw (15) translate it.
* Eyelids (19-22) turn the lid margins about the eyeball centre so that 3.1 / 3.2 drop (3.3 /
  3.4 rise) by exactly value x IRISD: the paper's hybrid eyelids.
* Eyeballs: yaw (23, 24) about +y, pitch (25, 26) about +x, in that order; thrust (27, 28)
  translates.
* Head: pitch (48), yaw (49), roll (50) about 7.1, as yaw * pitch * roll.
* Tongue (43-46): the default face's tongue is rigid on the jaw, so tip and body FAPs translate
  it whole (44 and 46 both raise it).
* Limits at pose time (``FapEngine.shown``), after the high-level FAPs are expanded; what a file
  says is never changed (the reader returns any finite value as written):

  - what no face can follow: a translation beyond ``TRANSLATION_LIMIT`` FAPU (twice its unit's
    reference distance, past every Greta editor range), a turn beyond half a turn (``HALF_TURN``),
    an eyeball turned beyond ``EYE_TURN`` (50 degrees, about a human eye's range) from ahead;
  - the jaw solver's reach: open_jaw beyond the drop at which 2.1 is lowest (highest) on its arc
    about the hinge (on the default face about 46 degrees open);
  - the lids' solver reach likewise, and lids crossing: an upper lid's drop plus its lower lid's
    rise is at most 1024 IRISD (IRISD0 is the rest opening / 1024: the margins meet there); past
    that, the closing parts are scaled back in proportion;
  - the rig's ``fap_reach``: the values this face shows without a fold, where a rig carries them.
    For the gaze FAPs (23-26) it caps only the lid skin they carry (``skin_reach``): the eyeball
    itself turns as far as asked, as eyes do past the point where the lids stop following;
  - then the rig's ``fap_follow``: of two FAPs whose feature points lie a hair's breadth apart
    (an inner and an outer lip point), the one with the larger value leads and the other follows just
    enough that the inner lip never slides through the outer one (their range of difference narrows
    as the two move together: ``puppet.runtime.follow``);
  - then the cheeks' crease limit: lift_cheek lowered as far as the skin under the eye needs, with
    whatever else the frame moves (``puppet.runtime.creaselimit``).

  ``shown(values)`` gives the values the face then shows, which is what ``encode`` measures back;
  within these limits they are the values themselves (``puppet.runtime.foldlimits`` finds reach and follow).

  ``puppet.fap.highlevel.limit_fields`` does the same for FAP 1 / 2 fields read from a file.
* High-level FAPs 1 and 2 expand into low-level FAPs (``puppet.fap.highlevel``) and add to the
  frame's low-level values.

``effects()`` says for every FAP what it does on this face, or why it does nothing (pupil dilation
is painted on the eyeball; the default face's ears are in its still region; tongue roll needs a
deformable tongue).

``FapEngine.encode(vertices)`` is the inverse: it measures the head, jaw, eyes, lids and tongue
rigidly (Kabsch fits on their vertices) and each translational FAP's feature point displacement in
the jaw's (or lid's) frame, so a take driven by other means can be written as standard FAPs.
"""

from __future__ import annotations

import copy
import functools
import math

import numpy as np

from puppet.face import rigid
from puppet.fap.highlevel import expand
from puppet.fap.table import N_FAPS, fap, faps
from puppet.runtime import follow
from puppet.runtime.creaselimit import CreaseLimit
from puppet.runtime.lastmade import LastMade
from puppet.runtime.lidclosure import LidClosure
from puppet.runtime.lids import LID_FAPS, LID_PAIRS, LID_PARTS

JAW_FAPS = (3, 14, 15)
EYE_FAPS = {"eye_l": (23, 25, 27), "eye_r": (24, 26, 28)}
GAZE_FAPS = (23, 24, 25, 26)
HEAD_FAPS = (48, 49, 50)
TONGUE_FAPS = (43, 44, 45, 46)
NOT_ON_ANY_FACE = {29: "the pupil is painted on the eyeball", 30: "the pupil is painted on the eyeball",
                   47: "the tongue is rigid: it cannot roll"}
X, Y, Z = np.eye(3)
TRANSLATION_LIMIT = 2048.0
HALF_TURN = math.pi / 1e-5
EYE_TURN = math.radians(50) / 1e-5
LIDS_MEET = 1024.0


def lid_shares(rig) -> dict[str, float]:
    """Each lid-carried control point's share of its lid's turn (``attach_weight``: 1 mid-lid, down
    to nearly 0 at the eye corners, which the canthal tendons hold still): how much of any motion of
    the lid margin it takes, a lid FAP's (``foldlimits.lid_faded``) or a muscle's (the runtime's
    control-point muscles)."""
    return {p.name: p.attach_weight for p in rig.control_points if p.attach in LID_PARTS}


class FapEngine:
    """FAP frames to runtime inputs (and back) for one face and rig."""

    def __init__(self, runtime) -> None:
        self.runtime = runtime
        self.face, self.rig = runtime.face, runtime.rig
        self._points = {p.name: p for p in self.rig.control_points}  # looked up every encoded frame
        self.fapu = self.face.fapu
        self.rest = np.asarray(self.face.vertices, dtype=float)
        self._index = {name: i for i, name in enumerate(runtime.control_points)}
        self._own = self._translation_matrix()
        self._translations = self._own + self._calibrated_matrix()
        self._moves = np.ascontiguousarray(self._translations.T, dtype=runtime.dtype)  # a FAP's motion a row
        self._moving = np.abs(self._translations).sum(axis=0) > 0  # the FAPs that move some point
        self._read_reach()
        self._read_follow()

    def _read_reach(self) -> None:
        """The face's limits and the rig's reach (the gaze FAPs' on the skin only) as arrays."""
        self.reach = self._face_limits()
        self.skin_reach = np.stack([np.full(N_FAPS, -np.inf), np.full(N_FAPS, np.inf)])
        for number, (low, high) in self.rig.fap_reach.items():
            limits = self.skin_reach if number in GAZE_FAPS else self.reach
            limits[0, number - 1] = max(limits[0, number - 1], low)
            limits[1, number - 1] = min(limits[1, number - 1], high)

    def _read_follow(self) -> None:
        """The rig's follow pairs as arrays: each pair's FAPs (0-based) and its range's half-planes."""
        pairs = sorted(self.rig.fap_follow.items())
        self._follow_a, self._follow_b = (np.array([pair[k] - 1 for pair, _ in pairs], dtype=np.int64) for k in (0, 1))
        self._follow_rows = np.array([follow.rows(*ranges) for _, ranges in pairs]).reshape(len(pairs), 4, 3)

    def on(self, runtime) -> FapEngine:
        """This engine for ``runtime``: this one's runtime with other follow pairs and reach
        (``Runtime.with_limits``) or other skin smoothing (``Runtime.with_smoothing``). The FAPs'
        motions and the lids' closing shapes stay (they move control points, which neither changes;
        the motions take 0.2 s to gather on a 27k-vertex face), the limits are read anew."""
        other = copy.copy(self)
        other.runtime, other.rig = runtime, runtime.rig
        other._read_reach()
        other._read_follow()
        return other

    def _face_limits(self) -> np.ndarray:
        """(2, 68) low / high: what this face can follow at all (see the module docstring)."""
        turns = np.array([f.unit == "AU" for f in faps()])
        limit = np.where(turns, HALF_TURN, TRANSLATION_LIMIT)
        limit[[n - 1 for n in GAZE_FAPS]] = EYE_TURN
        reach = np.stack([-limit, limit])
        parts = self.rig.rigid_parts
        solved = [(3, "jaw", "2.1", 1, "MNS0")]
        solved += [(n, part, point, sign, "IRISD0") for n, (part, point, sign) in LID_FAPS.items()]
        for number, part, point, sign, unit in solved:
            if part in parts:
                drops = _drop_reach(self._arc(part, point))
                low, high = np.sort(sign * drops / self.fapu[unit])
                reach[:, number - 1] = max(low, -TRANSLATION_LIMIT), min(high, TRANSLATION_LIMIT)
        return reach

    def shown(self, values: np.ndarray) -> np.ndarray:
        """The 68 low-level values this face shows for ``values`` (a new array): each within its
        reach, lids not crossing, then each follow pair within its range (module docstring)."""
        v = np.clip(np.asarray(values, dtype=float), self.reach[0], self.reach[1])
        for upper, lower in LID_PAIRS:
            excess = v[upper - 1] + v[lower - 1] - LIDS_MEET
            if excess > 0:
                closing = np.maximum(v[[upper - 1, lower - 1]], 0.0)
                v[[upper - 1, lower - 1]] -= excess * closing / closing.sum()
        a, b, rows = self._follow_a, self._follow_b, self._follow_rows
        outside = rows[:, :, 0] * v[a, None] + rows[:, :, 1] * v[b, None] - rows[:, :, 2]
        for k in np.flatnonzero(outside.max(axis=1, initial=0.0) > 0):  # the pairs share no FAP
            v[a[k]], v[b[k]] = follow.follower(rows[k], v[a[k]], v[b[k]])
        self._creases.limit(v)
        return v

    @functools.cached_property
    def _creases(self) -> CreaseLimit:
        return CreaseLimit(self)

    # -- decoding ------------------------------------------------------------------------

    def _translation_matrix(self) -> np.ndarray:
        """(K * 3, 68): displacement of every active point per unit of each translational FAP."""
        T = np.zeros((len(self._index), 3, N_FAPS))
        for f in faps():
            if f.unit in (None, "AU") or f.axis is None or f.number in JAW_FAPS + TONGUE_FAPS:
                continue
            if f.number in LID_FAPS or f.number in (27, 28):
                continue
            for point in f.feature_points:
                if point in self._index:
                    T[self._index[point], :, f.number - 1] += f.axis * self.fapu[f.unit]
        return T.reshape(-1, N_FAPS)

    def _calibrated_matrix(self) -> np.ndarray:
        """(K * 3, 68): the rig's calibrated FAP motions, in mesh units per unit of each FAP."""
        T = np.zeros((len(self._index), 3, N_FAPS))
        for number, motions in self.rig.fap_motions.items():  # a FAP's points at once: a point once per FAP
            names = [name for name in motions if name in self._index]
            if names:
                rows = np.array([self._index[name] for name in names], dtype=np.int64)
                T[rows, :, number - 1] += np.array([motions[name] for name in names]) * self.fapu[fap(number).unit]
        return T.reshape(-1, N_FAPS)

    def effects(self) -> dict[int, str]:
        """What each FAP does on this face (or why it does nothing), by FAP number."""
        moved = np.abs(self._own).sum(axis=0) > 0
        parts = self.rig.rigid_parts
        out = {}
        for f in faps():
            n = f.number
            if n in (1, 2):
                out[n] = "expands into low-level FAPs (data/high_level_faps.yaml)"
            elif n in NOT_ON_ANY_FACE:
                out[n] = f"nothing: {NOT_ON_ANY_FACE[n]}"
            elif n in JAW_FAPS:
                out[n] = "moves the jaw (rigid), the lower lip and chin follow"
            elif n in LID_FAPS:
                out[n] = f"turns the {LID_FAPS[n][0].replace('_', ' ')} margin about the eyeball"
            elif n in (23, 24, 25, 26, 27, 28):
                out[n] = "moves the eyeball (rigid)"
            elif n in HEAD_FAPS:
                out[n] = "turns the head about 7.1"
            elif n in TONGUE_FAPS:
                out[n] = "translates the tongue (rigid on the jaw)" if "tongue" in parts else "nothing: no tongue"
            elif moved[n - 1]:
                out[n] = f"moves control point {'/'.join(f.feature_points)}"
            else:
                out[n] = f"nothing: feature point {'/'.join(f.feature_points)} is not a control point of this rig"
        return out

    def low_level(self, values: np.ndarray, viseme: tuple | None = None,
                  expression: tuple | None = None) -> np.ndarray:
        """The 68 values with FAP 1 / FAP 2 expanded into low-level FAPs and added
        (``puppet.fap.highlevel.expand``)."""
        return expand(values, viseme, expression)

    def controls(self, values: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Control point displacements (K, 3, in the runtime's dtype) and the rigid motions of
        the parts that move, for 68 low-level FAP values as the face shows them (``shown``). A
        part whose FAPs are all 0 is at rest and left out; a part's motion is made again only
        when the FAPs it follows change (the motions are shared from frame to frame, so they are
        read-only). The displacements sum only the FAPs the frame shows: a take's frame shows
        few of them (the live slider box 21 of the 50 that move the skin)."""
        v = self.shown(values)
        d, motions = self._shown_controls(v)
        self._closure.add(v, d)
        return d, motions

    def _shown_controls(self, v: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``controls`` of values the face shows, without the lids' closing shapes."""
        skin = np.clip(v, self.skin_reach[0], self.skin_reach[1])
        showing = np.flatnonzero((skin != 0) & self._moving)
        d = (skin[showing].astype(self._moves.dtype) @ self._moves[showing]).reshape(-1, 3)
        moving = np.logical_or.reduceat(v[self._followed] != 0, self._first_followed)
        return d, {part: self._motion(part, make, v)
                   for (part, (make, _)), moves in zip(self._parts.items(), moving) if moves}

    @functools.cached_property
    def _parts(self) -> dict[str, tuple]:
        """{rigid part: (its motion from the 68 values, the FAPs (0-based) it follows)}."""
        parts = {"jaw": (self._jaw, [2, 13, 14]), "head": (self._head, [n - 1 for n in HEAD_FAPS])}
        for part, numbers in EYE_FAPS.items():
            parts[part] = (functools.partial(self._eye_of, part), [n - 1 for n in numbers])
        for number, (part, point, sign) in LID_FAPS.items():
            parts[part] = (functools.partial(self._lid_of, part, point, sign, number - 1), [number - 1])
        parts["tongue"] = (self._tongue, [n - 1 for n in TONGUE_FAPS])
        return {part: entry for part, entry in parts.items() if part in self.rig.rigid_parts}

    @property
    def closing_rows(self) -> np.ndarray:
        """The active control points (indices into ``control_points``) that the upper lids'
        closing shapes move: the margins' points other than feature points."""
        return np.concatenate([side.rows for side in self._closure.sides] + [np.zeros(0, np.int64)])

    @functools.cached_property
    def _closure(self) -> LidClosure:
        """The upper lids' closing shapes (``puppet.runtime.lidclosure``), sampled on first use."""
        return LidClosure(self.runtime, lambda values: self._shown_controls(self.shown(values)), LIDS_MEET)

    @functools.cached_property
    def _followed(self) -> np.ndarray:
        """The FAPs (0-based) the rigid parts follow, part after part in ``_parts`` order."""
        return np.concatenate([followed for _, followed in self._parts.values()]).astype(np.int64)

    @functools.cached_property
    def _first_followed(self) -> np.ndarray:
        """Where each part's FAPs start in ``_followed``."""
        return np.cumsum([0] + [len(followed) for _, followed in self._parts.values()][:-1])

    def _motion(self, part: str, make, v: np.ndarray) -> np.ndarray:
        return self._last_motions.get(part, v[self._parts[part][1]].tobytes(), lambda: make(v))

    @functools.cached_property
    def _last_motions(self) -> LastMade:
        return LastMade()

    def _eye_of(self, part: str, v: np.ndarray) -> np.ndarray:
        yaw, pitch, thrust = EYE_FAPS[part]
        return self._eye(part, v[yaw - 1], v[pitch - 1], v[thrust - 1])

    def _lid_of(self, part: str, point: str, sign: int, index: int, v: np.ndarray) -> np.ndarray:
        return self._lid(part, point, sign * v[index] * self.fapu["IRISD0"])

    def _jaw(self, v: np.ndarray) -> np.ndarray:
        drop = float(v[2]) * self.fapu["MNS0"]
        angle = _angle_for_drop(self._arc("jaw", "2.1"), drop)
        shift = (-float(v[14]) * self.fapu["MW0"], 0.0, float(v[13]) * self.fapu["MNS0"])  # along -x and +z
        return rigid.turn(*self._hinges["jaw"], angle, shift)

    def _lid(self, part: str, point: str, drop: float) -> np.ndarray:
        angle = _angle_for_drop(self._arc(part, point), drop)
        return rigid.turn(*self._hinges[part], angle)

    @functools.cached_property
    def _hinges(self) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]:
        """{hinged rigid part (the jaw, the lids): (its pivot, its axis)} as Python floats, for ``rigid.turn``."""
        return {name: (tuple(map(float, part.pivot)), tuple(map(float, part.axis)))
                for name, part in self.rig.rigid_parts.items() if part.axis is not None}

    def _arc(self, part: str, point: str) -> tuple[float, float, float]:
        """``_arc`` of a feature point about a rigid part's axis, made once."""
        key = (part, point)
        if key not in self._arcs:
            self._arcs[key] = _arc(self.face.feature_points[point] - self.rig.rigid_parts[part].pivot,
                                   self.rig.rigid_parts[part].axis)
        return self._arcs[key]

    @functools.cached_property
    def _arcs(self) -> dict[tuple[str, str], tuple[float, float, float]]:
        return {}

    def _eye(self, part: str, yaw: float, pitch: float, thrust: float) -> np.ndarray:
        au = self.fapu["AU"]
        R = rigid.rotation(Y, yaw * au) @ rigid.rotation(X, pitch * au)
        return rigid.about(self.rig.rigid_parts[part].pivot, R, thrust * self.fapu["ES0"] * Z)

    def _head(self, v: np.ndarray) -> np.ndarray:
        au = self.fapu["AU"]
        pitch, yaw, roll = (v[n - 1] * au for n in HEAD_FAPS)
        R = rigid.rotation(Y, yaw) @ rigid.rotation(X, pitch) @ rigid.rotation(Z, roll)
        return rigid.about(self.rig.rigid_parts["head"].pivot, R)

    def _tongue(self, v: np.ndarray) -> np.ndarray:
        mw, mns = self.fapu["MW0"], self.fapu["MNS0"]
        move = -v[42] * mw * X + (v[43] + v[45]) * mns * Y + v[44] * mw * Z
        return rigid.about(self.rig.rigid_parts["tongue"].pivot, np.eye(3), move)

    # -- encoding ------------------------------------------------------------------------

    def encode(self, vertices: np.ndarray) -> np.ndarray:
        """The 68 FAP values (FAP 1 and 2 left 0) that describe a deformed mesh of this face."""
        moved = np.asarray(vertices, dtype=float)
        out = np.zeros(N_FAPS)
        head = rigid.kabsch(self.rest[self._head_rows], moved[self._head_rows])
        out[[n - 1 for n in HEAD_FAPS]] = _yaw_pitch_roll(head[:, :3])[[1, 0, 2]] / self.fapu["AU"]
        local = rigid.apply(_inverse(head), moved)
        jaw = self._measure(local, "lower_teeth")
        self._encode_jaw(jaw, out)
        for part, (yaw, pitch, thrust) in EYE_FAPS.items():
            self._encode_eye(part, local, out, yaw, pitch, thrust)
        self._encode_lids(local, out)
        if "tongue" in self.rig.rigid_parts:
            self._encode_tongue(jaw, local, out)
        self._encode_translations(local, {"jaw": jaw}, out)
        return out

    def encode_skin(self, vertices: np.ndarray) -> np.ndarray:
        """``encode`` for a mesh whose rigid parts did not move (the head, jaw, eyes where they
        rest, as muscles leave them): the lid and translational FAPs only, without measuring
        the parts; what a muscle-driven pose adds to a take, once per frame."""
        local = np.asarray(vertices, dtype=float)
        out = np.zeros(N_FAPS)
        self._encode_lids(local, out)
        self._encode_translations(local, {}, out)
        return out

    def _encode_lids(self, local: np.ndarray, out: np.ndarray) -> None:
        for number, (_, point, sign) in LID_FAPS.items():
            p = self.face.feature_vertices[point]
            out[number - 1] = sign * (self.rest[p, 1] - local[p, 1]) / self.fapu["IRISD0"]

    @functools.cached_property
    def _head_rows(self) -> np.ndarray:
        """Vertices that only ever move with the head: the upper teeth."""
        return self.rig.region("upper_teeth").vertices

    def _measure(self, local: np.ndarray, region: str) -> np.ndarray:
        rows = self.rig.region(region).vertices
        return rigid.kabsch(self.rest[rows], local[rows])

    def _encode_jaw(self, jaw: np.ndarray, out: np.ndarray) -> None:
        part = self.rig.rigid_parts["jaw"]
        turn = rigid.about(part.pivot, jaw[:, :3])
        chin = self.face.feature_points["2.1"]
        out[2] = (chin[1] - rigid.apply(turn, chin[None])[0, 1]) / self.fapu["MNS0"]
        shift = jaw[:, 3] - turn[:, 3]
        out[13] = shift[2] / self.fapu["MNS0"]
        out[14] = -shift[0] / self.fapu["MW0"]

    def _encode_eye(self, part: str, local: np.ndarray, out: np.ndarray, yaw: int, pitch: int, thrust: int) -> None:
        eye = self._measure(local, "eyeball_l" if part == "eye_l" else "eyeball_r")
        angles = _yaw_pitch_roll(eye[:, :3])
        out[yaw - 1], out[pitch - 1] = angles[0] / self.fapu["AU"], angles[1] / self.fapu["AU"]
        centre = self.rig.rigid_parts[part].pivot
        out[thrust - 1] = (rigid.apply(eye, centre[None])[0, 2] - centre[2]) / self.fapu["ES0"]

    def _encode_tongue(self, jaw: np.ndarray, local: np.ndarray, out: np.ndarray) -> None:
        rows = self.rig.region("tongue").vertices
        own = rigid.kabsch(self.rest[rows], rigid.apply(_inverse(jaw), local[rows]))
        move = own[:, 3] - (self.rig.rigid_parts["tongue"].pivot - own[:, :3] @ self.rig.rigid_parts["tongue"].pivot)
        out[42] = -move[0] / self.fapu["MW0"]
        out[43] = move[1] / self.fapu["MNS0"]
        out[44] = move[2] / self.fapu["MW0"]

    @functools.cached_property
    def _own_axes(self) -> list[tuple[object, np.ndarray, np.ndarray]]:
        """(control point, FAP columns, their axes) for each point a translational FAP moves by
        definition: the few feature points among the rig's many control points."""
        T = self._own.reshape(len(self._index), 3, N_FAPS)
        plan = []
        for name, k in self._index.items():
            columns = np.flatnonzero(np.abs(T[k]).sum(axis=0))
            if len(columns):
                axes = T[k][:, columns].T
                plan.append((self._points[name], columns, axes / (axes * axes).sum(axis=1)[:, None]))
        return plan

    def _encode_translations(self, local: np.ndarray, motions: dict[str, np.ndarray], out: np.ndarray) -> None:
        """Each translational FAP from its point's own displacement (the part's motion undone)."""
        for point, columns, axes in self._own_axes:
            delta = local[point.vertex] - self.rest[point.vertex]
            out[columns] = axes @ _own_displacement(point, delta, motions.get(point.attach))


def _own_displacement(point, delta: np.ndarray, motion: np.ndarray | None) -> np.ndarray:
    """Invert the runtime's carrying of an attached point: delta = w (M(p0 + d) - p0) + (1 - w) d."""
    if motion is None:
        return delta
    w, R, t, p0 = point.attach_weight, motion[:, :3], motion[:, 3], point.position
    A = w * R + (1 - w) * np.eye(3)
    return np.linalg.solve(A, delta - w * (R @ p0 + t - p0))


def _arc(offset: np.ndarray, axis: np.ndarray) -> tuple[float, float, float]:
    """(A, radius, psi) of a point at ``offset`` from a pivot turning about ``axis``: turned by t,
    the y of its offset from the axis goes from A to radius cos(t - psi)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    r = offset - (offset @ a) * a
    A, C = float(r[1]), float(a[2] * r[0] - a[0] * r[2])  # C: (a x r)_y
    radius = math.hypot(A, C)
    return A, radius, math.atan2(C, A)


def _angle_for_drop(arc: tuple[float, float, float], drop: float) -> float:
    """The turn about the arc's axis that lowers its point by ``drop`` in y."""
    A, radius, psi = arc
    if radius < 1e-12 or drop == 0:
        return 0.0
    target = min(1.0, max(-1.0, (A - drop) / radius))
    return psi - math.copysign(math.acos(target), psi) if psi else math.acos(target)


def _drop_reach(arc: tuple[float, float, float]) -> np.ndarray:
    """(lowest, highest) drop ``_angle_for_drop`` can reach on an arc: its top and bottom."""
    A, radius, _ = arc
    return np.array([A - radius, A + radius])


def _yaw_pitch_roll(R: np.ndarray) -> np.ndarray:
    """Angles (about y, x, z) of R = Ry(yaw) Rx(pitch) Rz(roll)."""
    pitch = np.arcsin(np.clip(-R[1, 2], -1.0, 1.0))
    return np.array([np.arctan2(R[0, 2], R[2, 2]), pitch, np.arctan2(R[1, 0], R[1, 1])])


def _inverse(motion: np.ndarray) -> np.ndarray:
    R = motion[:, :3].T
    return np.hstack([R, (-R @ motion[:, 3])[:, None]])
