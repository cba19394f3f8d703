"""The root of every error facepuppet raises on purpose.

Each module's own error (``FapError``, ``MappingError``, ``TakeError`` ...) derives from
``PuppetError`` and keeps its built-in base (``ValueError``, ``OSError`` ...), so callers can catch
either. The command line catches ``PuppetError`` (and ``devices.base.DeviceError``, the device
layer's root) once and prints its one line; anything else escaping is a bug.
"""

from __future__ import annotations


class PuppetError(Exception):
    """An input, file or setting facepuppet refuses, with a message that names where and what."""
