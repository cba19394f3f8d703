"""facepuppet: live facial puppeteering on an MPEG-4 face rig.

The names below, and the submodules (``puppet.autorig``, ...), are imported when first used (PEP
562), so a command that needs none of them (``puppet devices``) does not pay for the face, the
rig and scipy.
"""

from importlib import import_module

_WHERE = {
    "PuppetError": "errors", "Face": "face", "load_face": "face", "Rig": "rig", "RigError": "rig",
    "load_rig": "rig", "save_rig": "rig", "Runtime": "runtime", "SibsonError": "sibson",
    "sibson_coordinates": "sibson", "FapError": "fapfile", "FapStream": "fapfile", "FapWarning": "fapfile",
    "FapWriter": "fapfile", "iter_fap": "fapfile", "read_fap": "fapfile", "write_fap": "fapfile",
    "MappingError": "mapping", "load_mapping": "mapping",
}
__all__ = list(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(import_module(f".{_WHERE[name]}", __name__), name)
    try:
        return import_module(f".{name}", __name__)
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
