"""Suite-wide setup: the unwrap cache (``baker/atlas/unwrap_cache.py``) of a test run is a
fresh temporary folder, never the user's ``~/.cache/baker``, so every run starts cold."""

import pytest


@pytest.fixture(autouse=True, scope="session")
def _fresh_unwrap_cache(tmp_path_factory):
    patch = pytest.MonkeyPatch()
    patch.setenv("BAKER_CACHE_DIR", str(tmp_path_factory.mktemp("baker-cache")))
    yield
    patch.undo()
