"""The face as data: the mesh and its feature points (the embedded default face, mesh files, face
folders, landmarks), its rig (regions, control points, rigid parts, muscle definitions) and the
auto-rig that builds one for any face with feature points.
"""
