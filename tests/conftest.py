"""Shared fixtures. Every test session gets its own coefficient cache: tests never read or write
the user's."""

import warnings

import moderngl
import numpy as np
import pytest
from window_keys import WindowKeys

from puppet.face.load import load_face
from puppet.runtime.runtime import Runtime


@pytest.fixture(autouse=True, scope="session")
def _private_coefficient_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("FACEPUPPET_CACHE", str(tmp_path_factory.mktemp("coefficients")))
    yield
    mp.undo()


@pytest.fixture(scope="session")
def face():
    """The default face (tests must not change it)."""
    return load_face()


@pytest.fixture(scope="session")
def runtime(face, _private_coefficient_cache):
    """The default face's runtime in float64, so exact properties can be checked exactly."""
    return Runtime(face, dtype=np.float64)


@pytest.fixture(scope="session")
def egl() -> None:
    """Skip, with the reason, where no headless EGL context can be made (no Mesa EGL here): the
    one reason a test that draws may skip. Once a context can be made, any renderer error fails."""
    try:
        moderngl.create_context(standalone=True, backend="egl").release()
    except Exception as exc:  # noqa: BLE001 -- whatever stops a context, its reason is the skip message
        pytest.skip(f"headless EGL OpenGL context unavailable: {exc}")


@pytest.fixture
def egl_context(egl):
    """A fresh standalone EGL context, released after the test."""
    ctx = moderngl.create_context(standalone=True, backend="egl")
    yield ctx
    ctx.release()


@pytest.fixture
def headless_window(egl):
    """Make a moderngl-window offscreen (EGL) window answering to a key table (``WindowKeys`` by
    default)."""
    def make(size: tuple[int, int], keys: type = WindowKeys):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PendingDeprecationWarning)
            import moderngl_window
        window = moderngl_window.get_local_window_cls("headless")(size=size, gl_version=(3, 3), backend="egl")
        window.keys = keys
        return window

    return make
