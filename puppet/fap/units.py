"""The face animation parameter units (FAPU, ISO/IEC 14496-2 Annex C): what makes a FAP value
unit-free. Five are distances between feature points of the neutral face, divided by 1024; the
sixth, AU, is an angle unit."""

FAPU_DEFINITIONS = {
    "IRISD0": ("3.1", "3.3", 1),
    "ES0": ("3.5", "3.6", 0),
    "ENS0": ("3.5", "9.15", 1),
    "MNS0": ("9.15", "2.2", 1),
    "MW0": ("8.3", "8.4", 0),
}
"""FAPU name -> (feature point a, feature point b, axis): the unit is (a[axis] - b[axis]) / 1024
measured on the neutral face."""

AU = 1e-5
"""The angle unit, radians."""
