"""A Pose to vertices, every frame: exact Sibson coordinates, weighted DFFD, control-point spreading,
the FAP engine (and its encoder), the muscle solver, normals, and the FAP calibration and fold
limits that shape a rig's motion.
"""
