"""facepuppet: live facial puppeteering on an MPEG-4 face rig."""

from .face import Face, load_face
from .rig import Rig, RigError, load_rig, save_rig
from .runtime import Runtime
from .sibson import SibsonError, sibson_coordinates

__all__ = [
    "Face", "load_face", "Rig", "RigError", "load_rig", "save_rig", "Runtime", "SibsonError",
    "sibson_coordinates",
]
