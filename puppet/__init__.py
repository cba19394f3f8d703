"""facepuppet: live facial puppeteering on an MPEG-4 face rig."""

from puppet.errors import PuppetError
from puppet.face.load import load_face
from puppet.face.model import Face
from puppet.face.rig import Rig, RigError, load_rig, save_rig
from puppet.io.fapfile import FapError, FapStream, FapWarning, FapWriter, iter_fap, read_fap, write_fap
from puppet.live.mappingfile import MappingError, load_mapping
from puppet.runtime.runtime import Runtime
from puppet.runtime.sibson import SibsonError, sibson_coordinates

__all__ = [
    "PuppetError", "Face", "load_face", "Rig", "RigError", "load_rig", "save_rig", "Runtime", "SibsonError",
    "sibson_coordinates",
    "FapError", "FapStream", "FapWarning", "FapWriter", "iter_fap", "read_fap", "write_fap",
    "MappingError", "load_mapping",
]
