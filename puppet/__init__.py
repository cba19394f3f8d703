"""facepuppet: live facial puppeteering on an MPEG-4 face rig."""

from .face import Face, load_face

__all__ = ["Face", "load_face"]
