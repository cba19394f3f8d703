"""The skin under the jaw line: an opening, shifting or thrusting jaw stretches it smoothly into
the still neck (no fold, no notch where jaw-carried skin meets the neck), and the neck below the
throat stays put (``puppet.face.autorig``: the jaw band)."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

import puppet
from puppet.runtime.musclesolver import folded_triangles

JAW_POSES = [{"open_jaw": 250}, {"open_jaw": 500}, {"open_jaw": 824},
             {"shift_jaw": 104}, {"shift_jaw": -104}, {"thrust_jaw": 300}, {"thrust_jaw": 600},
             {"open_jaw": 824, "shift_jaw": 104}]
"""Over the range the artist's shapes span (jawOpen: open_jaw 824; jawLeft / jawRight: shift_jaw
+-52, here twice that; thrust_jaw 0..600 MNS). Beyond, the calibrated motions extrapolate and fold
(the limits in the guide's contributors/realism.md)."""


@pytest.fixture(scope="module")
def face():
    return puppet.load_face()


@pytest.fixture(scope="module")
def runtime(face):
    return puppet.Runtime(face)


@pytest.fixture(scope="module")
def under_jaw(face):
    """Skin vertices on the jaw line (the face oval below the jaw angles) and below or behind it,
    down to the neck cut: where the jaw-carried face meets the neck."""
    v, tri = np.asarray(face.vertices), np.asarray(face.triangles)
    n, oval = len(v), np.asarray(face.contours["face_oval"])
    skin = np.zeros(n, dtype=bool)
    skin[face.parts["skin"]] = True
    on_oval = np.zeros(n, dtype=bool)
    on_oval[oval] = True
    e = np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e = e[skin[e].all(axis=1) & ~on_oval[e].any(axis=1)]
    _, comp = connected_components(sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
    nose = face.feature_vertices["9.3"]
    angle_y = face.feature_points["2.13"][1]
    neck_y = v[face.contours["neck_cut"], 1].max()
    return skin & (on_oval | (comp != comp[nose])) & (v[:, 1] <= angle_y) & (v[:, 1] > neck_y)


def _triangles_in(face, mask):
    tri = np.asarray(face.triangles)
    return tri[mask[tri].all(axis=1)]


@pytest.mark.parametrize("pose", JAW_POSES, ids=lambda p: ",".join(f"{k}={v}" for k, v in p.items()))
def test_no_fold_under_the_jaw(face, runtime, under_jaw, pose):
    tri = _triangles_in(face, under_jaw)
    folded = folded_triangles(runtime.deform_faps({}), runtime.deform_faps(pose), tri)
    assert not folded.any(), f"{int(folded.sum())} triangles fold under the jaw line"


@pytest.mark.parametrize("pose", JAW_POSES, ids=lambda p: ",".join(f"{k}={v}" for k, v in p.items()))
def test_neck_below_the_throat_stays(face, runtime, pose):
    fp = face.feature_points
    chin = fp["2.1"][1]
    neck = np.asarray(face.vertices)[:, 1] < chin - 0.5 * (fp["9.15"][1] - chin)
    moved = np.linalg.norm(runtime.deform_faps(pose) - runtime.deform_faps({}), axis=1)
    assert moved[neck].max() < 1e-9


@pytest.mark.parametrize("pose", [{"open_jaw": 824}, {"thrust_jaw": 600}, {"shift_jaw": 104}],
                         ids=lambda p: ",".join(f"{k}={v}" for k, v in p.items()))
def test_skin_under_the_chin_stretches_evenly(face, runtime, under_jaw, pose):
    """No edge under the jaw line shrinks to less than half or stretches to more than twice its
    length: the jaw's pull spreads over the band instead of piling up on one row of edges."""
    tri = _triangles_in(face, under_jaw)
    e = np.unique(np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1), axis=0)
    rest, posed = runtime.deform_faps({}), runtime.deform_faps(pose)
    ratio = (np.linalg.norm(posed[e[:, 0]] - posed[e[:, 1]], axis=1)
             / np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1))
    assert 0.5 < ratio.min() and ratio.max() < 2.0, (ratio.min(), ratio.max())


def test_displacement_eases_down_the_throat(face, runtime):
    """Down the mid-line from the chin to the neck the jaw's pull fades without a step: no
    vertex moves by more than 15% of the chin's motion away from its neighbours' average."""
    v = np.asarray(face.vertices)
    fp = face.feature_points
    chin = fp["2.1"]
    line = np.flatnonzero((np.abs(v[:, 0]) < 1e-3) & (v[:, 1] < chin[1] + 0.03) & (v[:, 2] > 0.2) & (v[:, 2] <= chin[2]))
    line = np.intersect1d(line, face.parts["skin"])
    line = line[np.argsort(-(v[line, 1] + v[line, 2]))]  # from the chin back under it, then down the throat
    d = runtime.deform_faps({"open_jaw": 824}) - runtime.deform_faps({})
    bend = np.linalg.norm(d[line[1:-1]] - (d[line[:-2]] + d[line[2:]]) / 2, axis=1)
    assert bend.max() < 0.15 * np.linalg.norm(d[face.feature_vertices["2.1"]])
