"""The face runtime: control point displacements and rigid motions in, vertex positions out.

Per frame (``deform``):

1. The caller gives displacements of the rig's active control points (``control_points``, in
   order) and rigid motions (3x4 ``[R | t]``) of the rig's rigid parts: ``jaw``, ``eye_l``,
   ``eye_r``, ``head`` and the lids ``upper_lid_l`` ... ``lower_lid_r``.
2. Points attached to a rigid part ride on it: the lower lip and chin points move with the jaw
   (their own displacement applied first, in the jaw's frame), which is how the jaw opens the
   mouth; the lid margin points turn about the eyeball centre (hybrid eyelids); the lip corners
   go half way with the jaw.
3. Fixed, interpolated (lip line) and passive points follow by one small dense product.
4. Every DFFD region moves its vertices by its weighted Sibson coefficients. In the precomputed
   mode all of this is folded into one sparse matrix B (vertices x inputs: the active points and
   the fixed points rigid parts carry; coefficients under ``prune`` of their row's largest are
   dropped, see ``_pruned``), so the skin costs a single sparse product written into the output
   (run over B's columns: ``_by_input``); in real-time mode each region applies
   its own coefficients and rebases them when a control point drifts farther than ``threshold``.
   Where the rig lists ``smoothed`` vertices (a face rigged by transfer), their motion is then
   averaged with their neighbours' (``puppet.runtime.skinsmoothing``): folded into B, or applied
   after the regions in the real-time mode.
5. On a pose (``deform_pose``, ``deform_faps``: FAPs, as a live face, a player or a fit deforms),
   the sliver guard (``puppet.runtime.sliverguard``) keeps the few triangles a closing lid turns
   over at the eye corners from folding (it checks them every frame and acts at a full blink), as
   the FAP engine keeps each FAP within its fold limits: both are limits of a pose. ``deform``
   itself moves the skin as the control points say (a random field of control-point motions
   squeezes the eye corners, and the guard would pay for sweeps there every frame).
6. Rigid regions (eyeballs, lower teeth, tongue) take their part's motion; then the whole head
   turns about 7.1, fading to nothing across the neck band so the bust base stays put.

The real-time mode is incremental, as the paper's: between rebases each region moves from the
skin and control points as they were at its last rebase, so the same pose reached by different
paths can differ slightly. The precomputed mode is path-free (and exact with ``prune=0``), and it
is the default.

Normals are recomputed only where the skin bends (DFFD regions, the neck band); rigid and still
parts turn their rest normals with their part and the head (the bust base below the neck band
does not turn).

Muscles (the rig's ``muscles``, ``muscle_names``; ``puppet.face.muscles``) join a frame as
``muscles={name: contraction}`` (0..1, more for experiments) in one of three ``MUSCLE_MODES``:

* ``control`` (Zhang & Chen, the default): each muscle moves the active control points inside its
  zone (improved law: none crosses its fixed end), carried by the rigid parts like the FAPs'
  displacements, and the rig's DFFD (B's columns for those points) spreads that share over the
  skin. DFFD alone folds the skin at large contraction (28 triangles at contraction 10 of the left
  zygomatic major on the default face, where the dragged lip corner meets the nose's and cheeks'
  anchored borders), so a **fold guard** runs on the muscles' share: the improved mode's edge
  constraints (``EdgeConstraints.relax``) over the triangles it reaches. B spreads the FAPs' and
  the muscles' shares in one product; the guard measures the muscles' share again on its own
  triangles' vertices only (``_guard_vertices``), and where it acts its correction is added. Per
  frame it checks only the triangles touching the vertices the moving inputs' columns of B reach
  (cached per set of moving inputs), and of those exactly only the ones whose corners drifted
  past their reach from a reference field (``EdgeConstraints._bad``): with nothing squeezed, a
  few whole-array steps and the share's sparse product. Its correction is a function of the
  share alone, so a held pose (the share of the last frame) adds the last correction and checks
  nothing. It acts only where a corner comes within 5% of
  its opposite edge (a triangle folds exactly when a corner crosses that edge), and then only on
  a few rings of triangles around those corners: sweeps, then scaling the share back toward rest
  there until no corner is that close, so no muscle folds the skin at any contraction. On the skin
  grid (``puppet.face.autorig``) a muscle moves many more points, and a few (the lids' orbicularis,
  the inner frontalis, risorius_r) squeeze a triangle at contraction 0.5-1: there the guard acts
  at normal contractions too, not only as the safety net for experiments beyond. It guards the
  muscles' share alone, like the improved vertex mode, because FAP poses legitimately squeeze
  the skin (a closed lid, an open jaw) and must draw as they always did. We chose it over changing
  the rig or the law on control points (sampling the muscle field at every control point, fixed
  anchors included, folded more, not less): it keeps the rig that FAP takes were made with.
  docs/muscle_experiment.md has the tables and timings.
* ``classic`` (Waters) and ``improved`` (Zhou & Liu): the FAPs' DFFD result plus
  ``MuscleModel``'s displacement of the skin vertices (the face's ``skin`` part, else the DFFD
  regions), before the rigid parts and the head turn.

With no muscle contracting (None, {} or every value 0) a frame is the FAP path, untouched.
"""

from __future__ import annotations

import copy
import difflib
import functools
import warnings
from collections.abc import Mapping

import numpy as np
import scipy.sparse as sp
from scipy.sparse import _sparsetools

from puppet.face.autorig import rig_for_face
from puppet.face.rig import Rig, rig_geometry_to_dict
from puppet.face.rigid import IDENTITY, compose
from puppet.fap.pose import Pose
from puppet.runtime import coefcache
from puppet.runtime.carry import Carry
from puppet.runtime.dffd import DffdError, RegionDeformer
from puppet.runtime.fapengine import FapEngine, lid_shares
from puppet.runtime.lastmade import LastMade
from puppet.runtime.musclesolver import ControlPointMuscles, EdgeConstraints, MuscleModel
from puppet.runtime.normals import VertexNormals
from puppet.runtime.skinsmoothing import skin_triangles, smoothing_matrix
from puppet.runtime.sliverguard import sliver_guard
from puppet.runtime.spreading import spread_matrix

MODES = ("precomputed", "realtime")
MUSCLE_MODES = ("control", "classic", "improved")


class Runtime:
    """A face and its rig, ready to deform every frame."""

    def __init__(self, face, rig: Rig | None = None, *, mode: str = "precomputed",
                 threshold: float | None = None, prune: float = 1e-3, dtype=np.float32,
                 cache: bool = True, guard: bool = True) -> None:
        if mode not in MODES:
            raise ValueError(f"mode {mode!r}: expected one of {MODES}")
        self.face = face
        self.rig = rig if rig is not None else rig_for_face(face)
        self.rig.validate()
        if self.rig.n_vertices != len(face.vertices):
            raise ValueError(f"rig is for {self.rig.n_vertices} vertices, face has {len(face.vertices)}")
        self.mode = mode
        self.prune = prune
        self.dtype = np.dtype(dtype)
        self.rest = np.ascontiguousarray(face.vertices, dtype=self.dtype)
        self.threshold = threshold if threshold is not None else _default_threshold(face)
        self._init_points()
        self._init_regions(cache)
        self._init_rigid()
        self._init_normals()
        self.muscle_names: tuple[str, ...] = tuple(m.name for m in self.rig.muscles)
        self._muscle_models: dict[str, MuscleModel] = {}
        self.few_inputs = False  # ``for_few_inputs``
        self._slivers = None  # the probes that find the sliver guard's triangles deform without it
        if guard:  # without: a runtime for checks that do without it (``puppet.runtime.creasesmoothing``)
            self._slivers = sliver_guard(self)

    # -- set-up ---------------------------------------------------------------------------

    def _init_points(self) -> None:
        rig = self.rig
        self._p0 = np.array([p.position for p in rig.control_points], dtype=float)
        index = rig.point_index()
        self.control_points: list[str] = rig.active_points
        inputs = rig.input_points
        self._inputs = np.array([index[n] for n in inputs], dtype=np.int64)
        points = [rig.control_points[index[n]] for n in inputs]
        weight = np.array([[p.attach_weight] for p in points])
        carried = {}  # part -> (its attached inputs, their rest positions, their weights)
        for part in rig.rigid_parts:
            idx = np.array([i for i, p in enumerate(points) if p.attach == part], dtype=np.int64)
            if part != "head" and len(idx):
                carried[part] = (idx, self._p0[self._inputs[idx]], weight[idx])
        self._carry = Carry(carried)

    def _init_regions(self, cache: bool) -> None:
        rig = self.rig
        index = rig.point_index()
        self._regions = [r for r in rig.regions if r.kind == "dffd"]
        self._region_cps = {r.name: np.array([index[c] for c in r.control_points]) for r in self._regions}
        self._driven = {
            r.name: np.array([i for i, p in enumerate(rig.control_points)
                              if p.role == "passive" and p.driver == r.name], dtype=np.int64)
            for r in self._regions
        }
        self.deformers = self._load_or_compute(cache)
        self._order = self._region_order()
        self._spread = spread_matrix(rig, self._passive_rows())
        self._interp = np.array([i for i, p in enumerate(rig.control_points) if p.role == "interpolated"],
                                dtype=np.int64)
        if self.mode == "precomputed":  # the real-time mode applies each region's own coefficients
            self.B = self._folded()
            self._by_input = sp.csc_matrix(self.B)  # the product's kernel: see ``_deform``
            self._by_input.sort_indices()

    def _queries(self, region) -> np.ndarray:
        return np.vstack([self.face.vertices[region.vertices], self._p0[self._driven[region.name]]])

    def _load_or_compute(self, cache: bool) -> dict[str, RegionDeformer]:
        """Each region's deformer from the coefficient cache, or computed (and then cached)."""
        key = coefcache.cache_key(self.face.content_hash, rig_geometry_to_dict(self.rig))  # muscle or FAP edits keep it
        cached = (coefcache.load(key) if cache else None) or {}
        deformers, computed = {}, False
        for region in self._regions:
            cps = self._region_cps[region.name]
            weights = [self.rig.control_points[i].weight for i in cps]
            queries = self._queries(region)
            box, sibson = cached.get(region.name, (None, None))
            if sibson is not None and sibson.shape == (len(queries), len(cps) + len(box)):
                deformers[region.name] = RegionDeformer.from_matrices(
                    region.name, queries, self._p0[cps], weights, box, sibson, self.rig.box_scale)
            else:
                deformers[region.name] = RegionDeformer(
                    region.name, queries, self._p0[cps], weights, self.rig.box_scale,
                    names=list(region.control_points))
                computed = True
        if cache and computed:
            coefcache.store(key, {n: (d.box, d.sibson) for n, d in deformers.items()})
        return deformers

    def _passive_rows(self) -> dict[str, dict[str, float]]:
        rows = {}
        names = [p.name for p in self.rig.control_points]
        for region in self._regions:
            deformer = self.deformers[region.name]
            cps = self._region_cps[region.name]
            nv = len(region.vertices)
            for j, point in enumerate(self._driven[region.name]):
                row = deformer.coefficients.getrow(nv + j)
                rows[names[point]] = {names[cps[c]]: float(w) for c, w in zip(row.indices, row.data)}
        return rows

    def _region_order(self) -> list:
        """DFFD regions ordered so that every passive point's driver comes before its users."""
        drivers = {r.name: {self.rig.control_points[i].driver for i in self._region_cps[r.name]
                            if self.rig.control_points[i].role == "passive"} for r in self._regions}
        order, done = [], set()
        while len(order) < len(self._regions):
            ready = [r for r in self._regions if r.name not in done and drivers[r.name] <= done]
            if not ready:
                raise ValueError(f"passive points make a cycle among regions {sorted(set(drivers) - done)}")
            order += ready
            done |= {r.name for r in ready}
        return order

    def _folded(self) -> sp.csr_matrix:
        """B: the regions' product smoothed where the rig says and pruned, as one CSR matrix (the
        precomputed mode's ``B``, from ``_regions_product``; a real-time runtime folds it only for
        muscles, from its regions' coefficients as they are, rebased or not)."""
        B = self._regions_product if self.mode == "precomputed" else self._product_of_regions()
        if len(self.rig.smoothed):
            B = self._smoothing @ B
        B = _pruned(sp.csr_matrix(B), self.prune)
        B = sp.csr_matrix(B, dtype=self.dtype)
        B.sort_indices()
        return B

    @functools.cached_property
    def _regions_product(self) -> sp.csr_matrix:
        """``_product_of_regions`` of a precomputed runtime, whose coefficients never change: made
        once and kept by ``with_smoothing``'s copies, whose smoothing does not change it (``puppet
        rig`` makes B without smoothing, then with it)."""
        return self._product_of_regions()

    def _product_of_regions(self) -> sp.csr_matrix:
        """The sum over regions of (its coefficients) @ (its rows of M), unsmoothed and unpruned
        (float64): what B is made from."""
        n = len(self.rest)
        spread = sp.csr_matrix(self._spread)  # rows sliced from one sparse M: the same entries as a block's own
        blocks = []
        for region in self._regions:
            coef = self.deformers[region.name].coefficients[: len(region.vertices)]
            folded = sp.csr_matrix(coef @ spread[self._region_cps[region.name]])  # sparse: the same sums in the
            folded.data[np.abs(folded.data) < 1e-12] = 0.0  # same order as a dense product (0.7 s on ICT)
            folded.eliminate_zeros()
            place = sp.csr_matrix((np.ones(len(region.vertices)), (region.vertices, np.arange(len(region.vertices)))),
                                  shape=(n, len(region.vertices)))
            blocks.append(place @ folded)
        return sum(blocks[1:], blocks[0]) if blocks else sp.csr_matrix((n, len(self._inputs)))

    @functools.cached_property
    def _smoothing(self) -> sp.csr_matrix:
        """The rig's skin smoothing (``puppet.runtime.skinsmoothing.smoothing_matrix``)."""
        return smoothing_matrix(skin_triangles(self.face), len(self.rest), self.rig.smoothed)

    @functools.cached_property
    def _smoothed_rows(self) -> sp.csr_matrix:
        """The smoothing's rows for the smoothed vertices: what the real-time mode applies."""
        return sp.csr_matrix(self._smoothing[self.rig.smoothed])

    def _init_rigid(self) -> None:
        self._rigid_vertices = {}
        for region in self.rig.regions:
            if region.kind == "rigid":
                prev = self._rigid_vertices.get(region.part, np.zeros(0, dtype=np.int64))
                self._rigid_vertices[region.part] = np.concatenate([prev, region.vertices]).astype(np.int64)
        self._rigid_rows = {part: _as_slice(v) for part, v in self._rigid_vertices.items()}
        self._part_buffers = {part: (np.empty((len(v), 3), self.dtype), np.empty((len(v), 3), self.dtype))
                              for part, v in self._rigid_vertices.items() if not isinstance(self._rigid_rows[part], slice)}
        head = self.rig.rigid_parts.get("head")
        self._neck_weight = np.ones(len(self.rest), dtype=self.dtype)
        if head is not None and head.neck is not None:
            lo, hi = head.neck
            s = np.clip((self.face.vertices[:, 1] - lo) / (hi - lo), 0.0, 1.0)
            self._neck_weight[:] = s * s * (3 - 2 * s)
        self._tmp = np.empty_like(self.rest)
        self._unturned = np.flatnonzero(self._neck_weight <= 0)
        self._neck_scale = np.repeat(self._neck_weight[:, None], 3, axis=1)  # (N, 3): no broadcast per frame

    @functools.cached_property
    def dffd_vertices(self) -> np.ndarray:
        """Bool mask of the vertices DFFD moves (the skin regions'; not the rigid parts)."""
        mask = np.zeros(len(self.rest), dtype=bool)
        for region in self._regions:
            mask[region.vertices] = True
        mask.setflags(write=False)
        return mask

    def _init_normals(self) -> None:
        """Normals are recomputed where the skin bends (DFFD regions and the neck band, with one
        ring of neighbours); rigid and still parts turn their rest normals instead."""
        tri = np.asarray(self.face.triangles, dtype=np.int64)
        bends = self.dffd_vertices | ((self._neck_weight > 0) & (self._neck_weight < 1))
        ring = np.zeros_like(bends)
        ring[tri[bends[tri].any(axis=1)].ravel()] = True
        self._bending = np.flatnonzero(ring | bends)
        self._bend_normals = VertexNormals(tri, len(self.rest), self._bending, dtype=self.dtype)
        self.rest_normals = VertexNormals(tri, len(self.rest))(self.face.vertices).astype(self.dtype)

    # -- per frame ------------------------------------------------------------------------

    def deform(self, displacements: np.ndarray, rigid: Mapping[str, np.ndarray] | None = None,
               *, out: np.ndarray | None = None, muscles: Mapping[str, float] | None = None,
               mode: str = "control") -> np.ndarray:
        """Vertex positions (N, 3) for active control point displacements (K, 3), rigid motions
        and muscle contractions {name: c} applied in ``mode`` (module docstring)."""
        return self._deform(displacements, self._checked(rigid), out, muscles, mode)

    def _deform(self, displacements: np.ndarray, rigid: dict[str, np.ndarray], out: np.ndarray | None,
                muscles: Mapping[str, float] | None, mode: str, *, pose: bool = False) -> np.ndarray:
        """``deform`` with the rigid motions checked (``_checked``); ``pose``: a pose's, with the
        sliver guard (module docstring)."""
        contracting = self._contracting(muscles, mode)
        d = self._effective(np.asarray(displacements, dtype=float), rigid)
        share = None
        if contracting and mode == "control":  # the muscles' share, attached points carried as the FAPs'
            share = self._muscle_share(contracting, rigid)
        if out is None:
            out = np.empty_like(self.rest)
        elif out.shape != self.rest.shape or out.dtype != self.dtype or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous {self.rest.shape} {self.dtype} array")
        if self.mode == "precomputed":
            if share is not None:  # one product spreads both shares; the guard corrects the muscles' alone
                d += share
            np.copyto(out, self.rest)
            self._spread_inputs(d.astype(self.dtype, copy=False), out)
        else:
            self._deform_realtime(d, out)
            if len(self.rig.smoothed):
                rows = self.rig.smoothed
                out[rows] = self.rest[rows] + self._smoothed_rows @ (out - self.rest)
            if share is not None:
                columns, spread = self._muscle_spread
                out += (spread @ share[columns]).astype(self.dtype, copy=False)
        if share is not None:
            self._guard_muscles(share[self._muscle_spread[0]], out)
        elif contracting:
            out += self._muscle_model(mode).displace(contracting).astype(self.dtype, copy=False)
        if pose and self._slivers is not None:
            self._slivers(out, rigid, np.asarray(displacements))
        for part in self._rigid_vertices:
            if part in rigid:
                self._move_part(part, self.rest, out, rigid[part][:, :3], rigid[part][:, 3])
        if "head" in rigid:
            self._turn_head(rigid["head"], out)
        return out

    def _spread_inputs(self, x: np.ndarray, out: np.ndarray) -> None:
        """``out += B @ x`` for the inputs' displacements ``x`` (K, 3), column by column (30% faster
        than by rows, and the same sums in the same order); ``for_few_inputs``, over the columns of
        the inputs that move alone."""
        B = self._by_input
        if not self.few_inputs:
            _sparsetools.csc_matvecs(B.shape[0], B.shape[1], 3, B.indptr, B.indices, B.data, x.ravel(), out.ravel())
            return
        moving = (x[:, 0] != 0) | (x[:, 1] != 0) | (x[:, 2] != 0)
        inputs, indptr, indices, data = self._last_columns.get("B", moving.tobytes(), lambda: _columns(B, moving))
        _sparsetools.csc_matvecs(B.shape[0], len(inputs), 3, indptr, indices, data, x[inputs].ravel(), out.ravel())

    @functools.cached_property
    def _last_columns(self) -> LastMade:
        """B's columns for the last set of inputs that moved (``for_few_inputs``)."""
        return LastMade()

    def for_few_inputs(self) -> Runtime:
        """This runtime for a caller that deforms the face many times with a few of its inputs
        moving, the same ones for a while (``puppet.runtime.foldsearch``: one FAP at a dozen
        values, moving 1,100-1,700 of ICT's 3,540 inputs; the sliver guard's probes, a lid and its
        brows): the product runs over B's columns for the inputs that move, gathered again only
        when they change (0.3-0.5 ms instead of 0.9 on ICT smoothed). The same sums in the same
        order, less the terms that add zero; a live face, whose inputs change from frame to frame,
        keeps the whole product."""
        other = copy.copy(self)
        other.few_inputs = True
        other.faps = self.faps  # one FAP engine for both, made once (it reads the runtime's geometry alone)
        return other

    def deform_with_normals(self, displacements: np.ndarray, rigid: Mapping[str, np.ndarray] | None = None,
                            *, out: np.ndarray | None = None, normals_out: np.ndarray | None = None,
                            muscles: Mapping[str, float] | None = None,
                            mode: str = "control") -> tuple[np.ndarray, np.ndarray]:
        """Positions and unit vertex normals for one frame."""
        return self._deform_with_normals(displacements, rigid, out, normals_out, muscles, mode)

    def _deform_with_normals(self, displacements: np.ndarray, rigid: Mapping[str, np.ndarray] | None,
                             out: np.ndarray | None, normals_out: np.ndarray | None,
                             muscles: Mapping[str, float] | None, mode: str, *,
                             pose: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``deform_with_normals``; ``pose`` as for ``_deform``."""
        rigid = self._checked(rigid)
        vertices = self._deform(displacements, rigid, out, muscles, mode, pose=pose)
        return vertices, self._normals(vertices, rigid, normals_out)

    # -- muscles ----------------------------------------------------------------------------

    def _contracting(self, muscles: Mapping[str, float] | None, mode: str) -> Mapping[str, float] | None:
        """``muscles`` when some muscle contracts (checked against this rig), else None."""
        if mode not in MUSCLE_MODES:
            raise ValueError(f"muscle mode {mode!r}: expected one of {MUSCLE_MODES}")
        if not muscles or not any(muscles.values()):
            return None
        unknown = [name for name in muscles if name not in self._muscle_set]
        if unknown:
            close = difflib.get_close_matches(unknown[0], self.muscle_names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ValueError(f"unknown muscle {unknown[0]!r}{hint} (this face has {len(self.muscle_names)} "
                             f"muscles: {', '.join(self.muscle_names) or 'none'})")
        return muscles

    @functools.cached_property
    def _muscle_set(self) -> frozenset[str]:
        return frozenset(self.muscle_names)

    @functools.cached_property
    def _control_muscles(self) -> ControlPointMuscles:
        """The muscles on the active control points' rest positions (control-point mode), the lid
        margin's points taking their share of the lid's turn."""
        return ControlPointMuscles(self.rig.muscles, self._p0[self._inputs[: len(self.control_points)]],
                                   self.muscle_shares)

    @functools.cached_property
    def muscle_shares(self) -> np.ndarray:
        """The part of a muscle's motion each active control point takes, in ``control_points``
        order: 1, except on the lid margins (``fapengine.lid_shares``)."""
        shares = lid_shares(self.rig)
        return np.array([shares.get(name, 1.0) for name in self.control_points])

    def control_positions(self, displacements: np.ndarray,
                          rigid: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        """Positions (K, 3) of the active control points for these displacements and rigid
        motions (as given to ``deform``): the points a part carries ride on its motion."""
        k = len(self.control_points)
        moved = self._effective(np.asarray(displacements, dtype=float), self._checked(rigid))
        return self._p0[self._inputs[:k]] + moved[:k]

    def points_moving(self, vertices: np.ndarray) -> np.ndarray:
        """Indices (into ``control_points``) of the active control points whose displacements DFFD
        spreads onto any of ``vertices``."""
        B = self.B if self.mode == "precomputed" else self._folded()
        columns = np.unique(sp.csr_matrix(B[np.asarray(vertices)]).indices)
        return columns[columns < len(self.control_points)]

    @functools.cached_property
    def _muscle_spread(self) -> tuple[np.ndarray, sp.csr_matrix]:
        """(the inputs some muscle moves, B's columns for them in float64): the control-point mode
        spreads the muscles' share of the inputs by this, apart from the FAPs' share."""
        columns = self._control_muscles.moved()
        B = self.B if self.mode == "precomputed" else self._folded()
        return columns, sp.csr_matrix(B[:, columns], dtype=float)

    @functools.cached_property
    def _fold_guard(self) -> EdgeConstraints:
        """Edge constraints over the triangles the muscles' share reaches, on those triangles'
        vertices alone (``_guard_vertices``, in that order); only DFFD vertices move."""
        return self._guard_set_up[1]

    @functools.cached_property
    def _guard_vertices(self) -> np.ndarray:
        """The fold guard's vertices (face numbering): where it measures and corrects the share."""
        return self._guard_set_up[0]

    @functools.cached_property
    def _guard_set_up(self) -> tuple[np.ndarray, EdgeConstraints, sp.csr_matrix]:
        """(the guard's vertices, its edge constraints, the rows of ``_muscle_spread`` for them)."""
        spread = self._muscle_spread[1]
        reached = np.diff(spread.indptr) > 0
        movable = self.dffd_vertices
        tri = np.asarray(self.face.triangles, dtype=np.int64)
        watched = tri[reached[tri].any(axis=1) & movable[tri].any(axis=1)]
        vertices, local = np.unique(watched, return_inverse=True)
        guard = EdgeConstraints(self.face.vertices[vertices], local.reshape(-1, 3), movable[vertices], reached[vertices])
        return vertices, guard, sp.csr_matrix(spread[vertices])

    def _guard_muscles(self, share: np.ndarray, out: np.ndarray) -> None:
        """The fold guard on the muscles' share ``share`` (their inputs, ``_muscle_spread``'s
        columns), measured on the guard's vertices alone; where it had to act, its correction is
        added to ``out`` (which already holds the share as DFFD spreads it). The correction is a
        function of the share alone, so a held pose reuses the last frame's."""
        share = np.ascontiguousarray(share, dtype=float)
        rows, correction = self._last_muscles.get("correction", share.tobytes(), lambda: self._guard_correction(share))
        out[rows] += correction

    def _guard_correction(self, share: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, what the fold guard adds to them) for the muscles' share ``share``."""
        vertices, guard, spread = self._guard_set_up
        moved = np.zeros((len(vertices), 3))  # spread @ share, without scipy's dispatch (a quarter of it)
        _sparsetools.csr_matvecs(spread.shape[0], spread.shape[1], 3, spread.indptr, spread.indices, spread.data,
                                 share.ravel(), moved.ravel())
        fixed = moved.copy()
        if not guard.relax(fixed, self._guarded(np.flatnonzero(np.any(share != 0, axis=1)))):
            return np.zeros(0, np.int64), np.zeros((0, 3), self.dtype)
        changed = np.flatnonzero(np.any(fixed != moved, axis=1))
        return vertices[changed], (fixed[changed] - moved[changed]).astype(self.dtype)

    @functools.cached_property
    def _last_muscles(self) -> LastMade:
        return LastMade()

    def _muscle_share(self, contracting: Mapping[str, float], rigid: Mapping[str, np.ndarray]) -> np.ndarray:
        """The muscles' share of the inputs (control-point mode: their displacements of the active
        points, carried by the parts as the FAPs' are), made again only when a contraction or a
        carrying part's motion changes: held sliders and a held jaw cost no muscle work."""
        muscles = self._control_muscles
        c = muscles.contractions(contracting)
        key = c.tobytes() + self._carry.key(rigid)
        return self._last_muscles.get("share", key, lambda: self._carried(muscles.displaced(c), rigid))

    def _guarded(self, moving: np.ndarray) -> np.ndarray:
        """The fold guard's triangles that the muscles' share can squeeze when it moves the inputs
        ``moving`` (positions in ``_muscle_spread``'s columns): those touching the vertices their
        columns of B reach, cached per set (a frame checks only these, not the whole skin)."""
        key = moving.tobytes()
        cache = self._guard_cache
        if key not in cache:
            if len(cache) >= 64:
                cache.clear()
            spread = self._guard_set_up[2]
            cache[key] = self._fold_guard.touching(np.diff(spread[:, moving].tocsr().indptr) > 0)
        return cache[key]

    @functools.cached_property
    def _guard_cache(self) -> dict[bytes, np.ndarray]:
        return {}

    def _muscle_model(self, mode: str) -> MuscleModel:
        """The vertex-mode model (made on first use) on the skin: the ``skin`` part, else the DFFD regions."""
        if mode not in self._muscle_models:
            skin = self.face.parts.get("skin")
            if skin is None:
                skin = np.concatenate([r.vertices for r in self._regions])
            self._muscle_models[mode] = MuscleModel(self.face.vertices, self.face.triangles, self.rig.muscles,
                                                    mode, movable=skin)
        return self._muscle_models[mode]

    def muscle_faps(self, muscles: Mapping[str, float], mode: str = "control") -> np.ndarray:
        """The 68 FAP values (FAPU) that the muscles' motion alone measures on the face
        (``FapEngine.encode_skin`` of the rest face deformed by them: muscles move no rigid part):
        how a muscle-driven pose is written to a .fap, added to the pose's own FAPs."""
        out = np.zeros(68)
        if self._contracting(muscles, mode):
            rest = np.zeros((len(self.control_points), 3))
            out = self.faps.encode_skin(self.deform(rest, muscles=muscles, mode=mode))
        return out

    def normals(self, vertices: np.ndarray, rigid: Mapping[str, np.ndarray] | None = None,
                *, out: np.ndarray | None = None) -> np.ndarray:
        """Unit normals of vertices deformed with these rigid motions (as given to ``deform``)."""
        return self._normals(vertices, self._checked(rigid), out)

    def _normals(self, vertices: np.ndarray, rigid: dict[str, np.ndarray], out: np.ndarray | None) -> np.ndarray:
        """``normals`` with the rigid motions checked (``_checked``)."""
        if out is None:
            out = np.empty_like(self.rest)
        head = rigid.get("head")
        turn = np.eye(3) if head is None else head[:, :3]
        if head is None:
            np.copyto(out, self.rest_normals)
        else:
            np.matmul(self.rest_normals, turn.T.astype(self.dtype), out=out)
            out[self._unturned] = self.rest_normals[self._unturned]
        for part in self._rigid_vertices:
            if part in rigid:
                self._move_part(part, self.rest_normals, out, turn @ rigid[part][:, :3])
        self._bend_normals(vertices, out, scatter=True)
        return out

    @functools.cached_property
    def faps(self) -> FapEngine:
        """This face's FAP engine (``puppet.runtime.fapengine.FapEngine``), made on first use."""
        return FapEngine(self)

    def with_limits(self, fap_follow: Mapping[tuple[int, int], tuple[float, ...]],
                    fap_reach: Mapping[int, tuple[float, float]] | None = None) -> Runtime:
        """This runtime on a copy of its rig with ``fap_follow`` (and ``fap_reach``, when given) in
        place of the rig's: only the FAP engine reads the limits (``FapEngine.on``), so
        the deformers, B and the sliver guard are shared and the copy costs no set-up (a new
        runtime of the ICT head, 27k vertices, takes 1-2 s). The fold-limit search tries a face
        under several follows, and ``foldlimits`` finds what the poses fold within the limits."""
        other = copy.copy(self)
        other.rig = copy.copy(self.rig)
        other.rig.fap_follow = dict(fap_follow)
        if fap_reach is not None:
            other.rig.fap_reach = dict(fap_reach)
        other.rig.validate()
        if "faps" in self.__dict__:
            other.faps = self.faps.on(other)
        return other

    def with_smoothing(self, smoothed: np.ndarray, *, guard: bool = True) -> Runtime:
        """This runtime on a copy of its rig whose ``smoothed`` vertices are ``smoothed``: the
        deformers (the Sibson coefficients, most of a runtime's set-up) are shared; B (when the
        vertices change), the sliver guard (unless ``guard`` is False) and everything made on first
        use are made again (``puppet.runtime.creasesmoothing`` smooths a face where it creased)."""
        other = copy.copy(self)
        other.__dict__ = {k: v for k, v in self.__dict__.items() if k not in _MADE_ON_USE}
        other.rig = copy.copy(self.rig)
        other.rig.smoothed = np.unique(np.asarray(smoothed, dtype=np.int64))
        other.rig.validate()
        if other.mode == "precomputed" and not np.array_equal(other.rig.smoothed, self.rig.smoothed):
            other.B = other._folded()
            other._by_input = sp.csc_matrix(other.B)
            other._by_input.sort_indices()
        if "faps" in self.__dict__:
            other.faps = self.faps.on(other)
        other._slivers = None
        if guard:
            other._slivers = sliver_guard(other)
        return other

    def deform_pose(self, pose: Pose, *, out: np.ndarray | None = None, normals_out: np.ndarray | None = None,
                    mode: str = "control", normals: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Positions and unit vertex normals of the face showing ``pose``: its FAPs, FAP 1 / 2
        blends and muscle contractions (in ``mode``), written into ``out`` and ``normals_out``
        when given (what a live loop or a player does every frame). ``normals`` False gives
        (positions, None): for a renderer that sums its own in the draw (``Renderer.gpu_normals``)."""
        d, motions = self.fap_controls(pose.fap, viseme=pose.viseme, expression=pose.expression)
        if normals:
            return self._deform_with_normals(d, motions, out, normals_out, pose.muscles, mode, pose=True)
        return self._deform(d, self._checked(motions), out, pose.muscles, mode, pose=True), None

    def deform_faps(self, fap: Mapping[int | str, float] | np.ndarray | None = None, *,
             viseme: tuple | None = None, expression: tuple | None = None,
             muscles: Mapping[str, float] | None = None, mode: str = "control",
             out: np.ndarray | None = None) -> np.ndarray:
        """Vertices for MPEG-4 FAPs: {number or name: value} (or 68 values, index 0 = FAP 1), in
        FAPU units as in a .fap file, plus FAP 1 (select1, select2, blend) and FAP 2 (select1,
        intensity1, select2, intensity2) blends, and muscle contractions {name: c} (``muscle_names``;
        0..1, more for experiments) in ``mode`` (``MUSCLE_MODES``, module docstring). Unknown names
        name the closest FAP or muscle."""
        d, motions = self.fap_controls(fap, viseme=viseme, expression=expression)
        return self._deform(d, self._checked(motions), out, muscles, mode, pose=True)

    def fap_controls(self, fap: Mapping[int | str, float] | np.ndarray | None = None, *,
                     viseme: tuple | None = None,
                     expression: tuple | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The displacements and rigid motions ``deform_faps`` deforms with."""
        from puppet.fap.highlevel import fap_values

        if fap is None:
            values = np.zeros(68)
        elif isinstance(fap, Mapping):
            values = fap_values(fap)
        else:
            values = np.asarray(fap, dtype=float)
        return self.faps.controls(self.faps.low_level(values, viseme, expression))

    def _checked(self, rigid: Mapping[str, np.ndarray] | None) -> dict[str, np.ndarray]:
        """The rigid motions as float arrays, each a 3x4 [R | t] for a part this rig has, less
        those that do not move (a part at rest costs nothing: the FAP engine gives every part a
        motion every frame, most of them the identity)."""
        rigid = {k: np.asarray(m, dtype=float) for k, m in (rigid or {}).items()}
        unknown = set(rigid) - set(self.rig.rigid_parts)
        if unknown:
            raise ValueError(f"unknown rigid motions {sorted(unknown)}; this rig has {sorted(self.rig.rigid_parts)}")
        for name, motion in rigid.items():
            if motion.shape != (3, 4):
                raise ValueError(f"rigid motion {name!r} must be a 3x4 [R | t] matrix, got shape {motion.shape}")
        for name, parent in self._parents:
            if parent in rigid:
                rigid[name] = self._composed(name, rigid[parent], rigid.get(name, IDENTITY))
        if not rigid:
            return rigid
        still = (np.stack(list(rigid.values())) == IDENTITY).all(axis=(1, 2))
        return {name: motion for (name, motion), rest in zip(rigid.items(), still) if not rest}

    @functools.cached_property
    def _parents(self) -> list[tuple[str, str]]:
        """(part, its parent) for the rig's parts that ride on another (parents first, as the rig lists them)."""
        return [(name, part.parent) for name, part in self.rig.rigid_parts.items() if part.parent is not None]

    def _composed(self, name: str, outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
        """``compose(outer, inner)`` for part ``name``, kept while its two motions stay the same
        (a held jaw carries the tongue: the same motion every frame)."""
        return self._last_composed.get(name, outer.tobytes() + inner.tobytes(), lambda: compose(outer, inner))

    @functools.cached_property
    def _last_composed(self) -> LastMade:
        return LastMade()

    def _move_part(self, part: str, source: np.ndarray, out: np.ndarray, R: np.ndarray,
                   t: np.ndarray | None = None) -> None:
        """A rigid part's rows of ``source`` turned by R (and moved by t), written into ``out``:
        straight through views when the part's vertices are one run (the default face's are),
        else gathered into and scattered from the part's buffers."""
        rows, R = self._rigid_rows[part], R.T.astype(self.dtype)
        if isinstance(rows, slice):
            moved = np.matmul(source[rows], R, out=out[rows])
        else:
            taken, moved = self._part_buffers[part]
            np.take(source, rows, axis=0, out=taken)
            np.matmul(taken, R, out=moved)
        if t is not None:
            _translate(moved, t.astype(self.dtype))
        if not isinstance(rows, slice):
            out[rows] = moved

    def _effective(self, d: np.ndarray, rigid: Mapping[str, np.ndarray]) -> np.ndarray:
        """The inputs (active points, then the fixed points parts carry) for displacements ``d``
        of the active points: attached points ride on their parts' motions."""
        k = len(self.control_points)
        if d.shape != (k, 3):
            raise ValueError(f"displacements must be ({k}, 3), got {d.shape}")
        out = np.zeros((len(self._inputs), 3))
        out[:k] = d
        self._carry.carry(out, rigid)
        return out

    def _carried(self, extra: np.ndarray, rigid: Mapping[str, np.ndarray]) -> np.ndarray:
        """What ``extra`` displacements (K, 3) add to ``_effective``'s inputs: its carry is affine
        in the displacements, so an addition is carried by the rotations alone."""
        out = np.zeros((len(self._inputs), 3))
        out[: len(extra)] = extra
        self._carry.turn(out, rigid)
        return out

    def _turn_head(self, motion: np.ndarray, out: np.ndarray) -> None:
        tmp = self._tmp
        np.matmul(out, motion[:, :3].T.astype(self.dtype), out=tmp)
        _translate(tmp, motion[:, 3].astype(self.dtype))
        tmp -= out
        tmp *= self._neck_scale
        out += tmp

    def _deform_realtime(self, d: np.ndarray, out: np.ndarray) -> None:
        """Each region from its reference state; rebase regions whose points drifted past T."""
        points = self._p0.copy()
        points[self._inputs] += d
        points[self._interp] = self._p0[self._interp] + self._spread[self._interp] @ d
        np.copyto(out, self.rest)
        for region in self._order:
            deformer = self.deformers[region.name]
            cps = self._region_cps[region.name]
            q = deformer.queries + deformer.coefficients @ (points[cps] - deformer.sites)
            nv = len(region.vertices)
            out[region.vertices] = q[:nv]
            points[self._driven[region.name]] = q[nv:]
            drift = np.linalg.norm(points[cps] - deformer.sites, axis=1)
            if drift.max(initial=0.0) > self.threshold:
                self._rebase(deformer, q, points[cps])

    @staticmethod
    def _rebase(deformer: RegionDeformer, queries: np.ndarray, sites: np.ndarray) -> None:
        """Rebase one region; if the pose cannot be rebased (two control points dragged onto each
        other), keep the old coefficients: the face goes on moving, only less exactly."""
        try:
            deformer.rebase(queries, sites)
        except DffdError as exc:
            warnings.warn(f"real-time rebase skipped: {exc}", stacklevel=3)


_MADE_ON_USE = frozenset(name for name, value in vars(Runtime).items()
                         if isinstance(value, functools.cached_property)) - {"_regions_product"}
"""What a runtime makes on first use (its ``functools.cached_property`` names): a copy on another
rig (``with_smoothing``) makes it again, except the regions' product, which smoothing leaves as
it is."""


def _pruned(B: sp.csr_matrix, prune: float) -> sp.csr_matrix:
    """B without the entries below ``prune`` x their row's largest, each row's dropped sum added to
    that largest entry.

    Far-away inputs reach a vertex through tiny coefficients: dropping those under 1e-3 of the
    row's largest removes about 30% of B's entries (and of the per-frame work). The error is
    bounded row by row: a vertex moves by at most the magnitude its row dropped (under 1e-3 of
    its largest entry per entry dropped) times the largest difference between two of its inputs'
    displacements; on the demo take that is at most 0.2-0.4% of the largest displacement (the guide,
    contributors/deformation.md). Keeping each row's sum keeps what matters exactly: a region
    translates with its points, a direct point moves its vertex by exactly its displacement, no
    displacement gives the rest mesh.
    """
    if prune <= 0 or B.nnz == 0:
        return B
    B = B.copy()
    rows = np.repeat(np.arange(B.shape[0]), np.diff(B.indptr))
    magnitude = np.abs(B.data)
    largest = np.zeros(B.shape[0])
    np.maximum.at(largest, rows, magnitude)
    drop = magnitude < prune * largest[rows]
    dropped = np.bincount(rows[drop], weights=B.data[drop], minlength=B.shape[0])
    keeper = np.flatnonzero(magnitude == largest[rows])
    keeper = keeper[np.unique(rows[keeper], return_index=True)[1]]
    B.data[keeper] += dropped[rows[keeper]]
    B.data[drop] = 0.0
    B.eliminate_zeros()
    return B


def _columns(B: sp.csc_matrix, inputs: np.ndarray) -> tuple[np.ndarray, ...]:
    """(the inputs, then indptr, indices and data of ``B``'s columns for them) for a bool mask
    ``inputs`` over B's columns: a CSC matrix of those columns, in their order."""
    inputs = np.flatnonzero(inputs)
    starts, counts = B.indptr[inputs], np.diff(B.indptr)[inputs]
    indptr = np.zeros(len(inputs) + 1, dtype=B.indptr.dtype)
    np.cumsum(counts, out=indptr[1:])
    taken = np.repeat(starts - indptr[:-1], counts) + np.arange(indptr[-1], dtype=B.indptr.dtype)
    return inputs, indptr, B.indices[taken], B.data[taken]


def _translate(points: np.ndarray, t: np.ndarray) -> None:
    """``points += t`` for points (n, 3), a column at a time: the same sums, 2.5x faster than
    numpy's broadcast over rows of 3."""
    for k in range(3):
        points[:, k] += t[k]


def _as_slice(indices: np.ndarray) -> slice | np.ndarray:
    """A run of consecutive indices as a slice (views, no copies), else the indices."""
    if len(indices) and np.array_equal(indices, np.arange(indices[0], indices[0] + len(indices))):
        return slice(int(indices[0]), int(indices[0]) + len(indices))
    return indices


def _default_threshold(face) -> float:
    """T for real-time mode: 2% of the face's height."""
    extent = np.ptp(np.asarray(face.vertices), axis=0)
    return 0.02 * float(extent[1])

