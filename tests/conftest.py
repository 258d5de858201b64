"""Suite-wide setup.

- The unwrap cache (``baker/atlas/unwrap_cache.py``) of a test run is a fresh temporary folder,
  never the user's ``~/.cache/baker``, so every run starts cold.
- Long mode: a test marked ``@pytest.mark.long`` (generated cases by the thousand, million-
  triangle levels, installs into new virtual environments) runs only when ``BAKER_LONG=1`` is
  set; the default run leaves it out (deselected, counted on pytest's summary line), so that the
  default suite stays within its time budget on 2 cores. ``BAKER_LONG=1 bash .ci/run`` runs all.
- Side by side: the README runs the suite on every core (pytest-xdist), each worker a process
  of its own taking whichever test is next. So a test writes only in its own temporary folder,
  never in the checkout (``test_warm_kernels.py`` warms a copy of the package), takes a port
  from the system (``ray_cluster.free_port``), and holds ``machine_lock`` while it makes what
  the machine has once (Chromium's install, a folder's npm packages).
"""

import os

import pytest

LONG = bool(os.environ.get("BAKER_LONG"))


def pytest_configure(config):
    config.addinivalue_line("markers", "long: a slow case, run only with BAKER_LONG=1")


def pytest_collection_modifyitems(config, items):
    """Leave the long cases out of a default run."""
    if LONG:
        return
    slow = [item for item in items if item.get_closest_marker("long") is not None]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if item.get_closest_marker("long") is None]


@pytest.fixture(autouse=True, scope="session")
def _fresh_unwrap_cache(tmp_path_factory):
    patch = pytest.MonkeyPatch()
    patch.setenv("BAKER_CACHE_DIR", str(tmp_path_factory.mktemp("baker-cache")))
    yield
    patch.undo()
