"""Subdividing the default face keeps its feature points, parts and loops meaningful."""

import numpy as np

from puppet.face.load import load_face
from puppet.face.subdivide import subdivide


def test_subdividing_the_skin_keeps_indices_and_closes_loops():
    face = load_face()
    fine = subdivide(face)
    skin = len(face.parts["skin"])
    assert 3.5 * skin < len(fine.parts["skin"]) < 4.5 * skin
    assert len(fine.parts["eye_l"]) == len(face.parts["eye_l"])
    np.testing.assert_array_equal(fine.vertices[: len(face.vertices)], face.vertices)
    for fdp, vertex in face.feature_vertices.items():
        np.testing.assert_array_equal(fine.vertices[fine.feature_vertices[fdp]], face.vertices[vertex])
    edges = {tuple(sorted(e)) for t in fine.triangles for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    loop = fine.contours["mouth_opening"]
    assert len(loop) == 2 * len(face.contours["mouth_opening"])
    assert all(tuple(sorted((int(p), int(q)))) in edges for p, q in zip(loop, np.roll(loop, -1)))
