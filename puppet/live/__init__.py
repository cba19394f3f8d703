"""The live session: mappings from a performer's channels to Poses, filters, device calibration,
the take clock, recording, retakes of a recorded log, and ARKit imports.
"""
