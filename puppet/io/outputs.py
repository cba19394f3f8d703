"""Files a command is about to write: checked before any work, so a bad ``-o`` is one line.

A render or replay that fails on its output only at the end (ffmpeg's pipe breaking, a folder
that is not there) wastes the work and blames the wrong thing; ``writable`` says what is wrong
with the path first.
"""

from __future__ import annotations

import os
from pathlib import Path

from puppet.errors import PuppetError


class OutputError(PuppetError, OSError):
    """An output path that cannot be written: the message names it and why."""

    def __str__(self) -> str:
        return str(self.args[0])


def writable(path: str | os.PathLike[str], what: str = "file") -> Path:
    """``path`` as a Path, if a ``what`` can be written there: its folder exists and is writable,
    and it is not itself a folder."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise OutputError(f"{path}: expected a {what} to write, found a folder")
    if not folder.is_dir():
        raise OutputError(f"{path}: cannot write the {what}: there is no folder {folder}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: cannot write the {what}: the folder {folder} is not writable")
    return path
