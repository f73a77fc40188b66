"""Shared fixtures: the world and its jitted settle function are built once per session
(compiling an MJX step costs tens of seconds on two cores); the fixtures several files share
are in helpers/fixtures.py, the shared stand-ins and scenes in helpers/ (tests/helpers/__init__.py)."""
import atexit
import os
import shutil
import tempfile

# Programs compiled in this session go to an on-disk JAX cache shared with the subprocesses
# the tests start (notebook kernels, CLI runs): they then load a program instead of compiling
# it again (minutes each on two cores). Set before JAX is imported; an outer setting wins.
# Under pytest-xdist the main process sets it before it starts the workers, which inherit it:
# one folder, so a program compiled on one worker is loaded on the other.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _cache = tempfile.mkdtemp(prefix="relaff-jax-cache-")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _cache
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
# No traced program is kept or read (relaff_jax/sim/traced_cache.py) by this session or the
# commands it starts: they share one compilation cache, and a test that monkeypatches a module
# changes what a trace would be without changing its file name (tests/sim/test_traced_cache.py
# turns the store on in a private folder).
os.environ["RELAFF_TRACE_STORE"] = "0"


def _preload_libusb() -> None:
    """Open3D's wheel links the system library libusb-1.0.so.0, which a fresh machine may
    lack; the ``libusb-package`` wheel (a test extra) ships it. Loaded globally before Open3D
    is imported, it satisfies that dependency with no system package."""
    import ctypes
    import ctypes.util

    if ctypes.util.find_library("usb-1.0"):
        return
    try:
        import libusb_package
    except ImportError:
        return
    path = libusb_package.get_library_path()
    if path is not None:
        ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)


_preload_libusb()

import pytest  # noqa: E402

from relaff_jax.sim import scenes, world  # noqa: E402

# workers: an xdist worker's cores and the units of work (helpers/workers.py); times: RELAFF_TEST_TIMES
pytest_plugins = ["helpers.workers", "helpers.fixtures", "helpers.times"]


@pytest.fixture(scope="session")
def scene_world():
    return world.build_world()


@pytest.fixture(scope="session")
def settle(scene_world):
    """jitted ``settle_fn(pair, qpos0, intended)`` of the default config."""
    return scenes.jitted_scene_fns(scene_world)[1]
