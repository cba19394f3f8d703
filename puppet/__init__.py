"""facepuppet: live facial puppeteering on an MPEG-4 face rig.

The package is layered by the data flow, each layer importing only those below it: ``puppet.fap``
(the FAP table, units, frames, high-level FAPs, Pose), ``puppet.io`` (.fap files, takes, their
logs), ``puppet.face`` (the face model and its rig), ``puppet.runtime`` (a Pose to vertices),
``puppet.photo`` (a face from a photo), ``puppet.live`` (mappings, the live session, retakes),
``puppet.view`` (renderer, windows, video and glTF) and ``puppet.bench``; ``puppet.cli`` is the
``puppet`` command. The devices a performer works are the ``devices`` package, below them all.

The names below are imported when first used (PEP 562), so a command that needs none of them
(``puppet devices``) does not pay for the face, the rig and scipy.
"""

from importlib import import_module

_WHERE = {
    "PuppetError": "puppet.errors",
    "Face": "puppet.face.model", "load_face": "puppet.face.load",
    "Rig": "puppet.face.rig", "RigError": "puppet.face.rig", "load_rig": "puppet.face.rig",
    "save_rig": "puppet.face.rig",
    "Pose": "puppet.fap.pose",
    "Runtime": "puppet.runtime.runtime",
    "SibsonError": "puppet.runtime.sibson", "sibson_coordinates": "puppet.runtime.sibson",
    "FapError": "puppet.io.fapfile", "FapStream": "puppet.io.fapfile", "FapWarning": "puppet.io.fapfile",
    "FapWriter": "puppet.io.fapfile", "iter_fap": "puppet.io.fapfile", "read_fap": "puppet.io.fapfile",
    "write_fap": "puppet.io.fapfile",
    "MappingError": "puppet.live.mappingfile", "load_mapping": "puppet.live.mappingfile",
}
__all__ = list(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(import_module(_WHERE[name]), name)
    try:
        return import_module(f".{name}", __name__)
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
