"""Files: .fap streams (read exactly, written crash-safe), take folders, a take's raw log and its
events, output paths, and the mappings the package ships.
"""
