"""facepuppet: live facial puppeteering on an MPEG-4 face rig."""

from .errors import PuppetError
from .face import Face, load_face
from .fapfile import FapError, FapStream, FapWarning, FapWriter, iter_fap, read_fap, write_fap
from .mapping import MappingError, load_mapping
from .rig import Rig, RigError, load_rig, save_rig
from .runtime import Runtime
from .sibson import SibsonError, sibson_coordinates

__all__ = [
    "PuppetError", "Face", "load_face", "Rig", "RigError", "load_rig", "save_rig", "Runtime", "SibsonError",
    "sibson_coordinates",
    "FapError", "FapStream", "FapWarning", "FapWriter", "iter_fap", "read_fap", "write_fap",
    "MappingError", "load_mapping",
]
