"""Every test session gets its own coefficient cache: tests never read or write the user's."""

import pytest


@pytest.fixture(autouse=True, scope="session")
def _private_coefficient_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("FACEPUPPET_CACHE", str(tmp_path_factory.mktemp("coefficients")))
    yield
    mp.undo()
