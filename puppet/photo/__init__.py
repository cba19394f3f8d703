"""A performer's face from one photo: landmarks found (or given), the default face fitted and
textured, rigged like any other face.
"""
