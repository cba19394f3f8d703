"""The mappings facepuppet ships, found by name wherever the package is installed.

They live in the repository's ``mappings/`` folder; a wheel installs that folder as package data
(``puppet/mappings``, see ``pyproject.toml``), so ``--mapping arduino_sliders`` works from any
folder after a plain ``pip install .``, and from a source checkout too.
"""

from __future__ import annotations

import difflib
import shutil
from pathlib import Path

from puppet.errors import PuppetError

_PACKAGE = Path(__file__).resolve().parents[1]  # the puppet package


class MappingNotFound(PuppetError, FileNotFoundError):
    """A ``--mapping`` that is neither a file nor the name of a shipped mapping."""


class MappingExists(PuppetError, FileExistsError):
    """A copy of a shipped mapping would overwrite a file."""


def mappings_folder() -> Path:
    """Where the shipped mappings are: installed package data, else the checkout's ``mappings/``."""
    installed = _PACKAGE / "mappings"
    return installed if installed.is_dir() else _PACKAGE.parent / "mappings"


def shipped_mappings() -> dict[str, Path]:
    """The shipped mappings by name (the file's stem), sorted."""
    return {p.stem: p for p in sorted(mappings_folder().glob("*.yaml"))}


def mapping_path(name_or_path: str | Path) -> Path:
    """A mapping file: ``name_or_path`` itself when it exists, else the shipped mapping of that name
    (with or without ``.yaml``)."""
    path = Path(name_or_path)
    if path.exists():
        return path
    return shipped_mapping(str(name_or_path))


def shipped_mapping(name: str) -> Path:
    """The shipped mapping ``name`` (with or without ``.yaml``)."""
    shipped = shipped_mappings()
    stem = name[:-5] if name.endswith(".yaml") else name
    if stem in shipped:
        return shipped[stem]
    close = difflib.get_close_matches(stem, shipped, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    raise MappingNotFound(f"{name}: no such mapping file, and no shipped mapping of that name{hint} "
                          f"(shipped: {', '.join(shipped)}; `puppet mappings` lists them)")


def copy_mapping(name: str, destination: str | Path = ".") -> Path:
    """Write an editable copy of the shipped mapping ``name`` into ``destination`` (a folder, or the
    new file's path); an existing file is never overwritten."""
    source = shipped_mapping(name)
    destination = Path(destination)
    target = destination / source.name if destination.is_dir() else destination
    if target.exists():
        raise MappingExists(f"{target}: already exists; not overwritten (give another path)")
    shutil.copyfile(source, target)
    return target
