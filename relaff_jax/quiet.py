"""Quiet imports: MJX's optional GPU backend announces its absence on stdout.

``mujoco.mjx`` tries to import Warp and prints "Failed to import warp" / "Failed to import
mujoco_warp" when it is missing: always, on this CPU-only project, and a new user takes it
for an error. ``install()`` wraps the import of ``mujoco.mjx.warp`` (once, the first time
anything imports MJX) so that what it prints is dropped; nothing else is affected.
"""
from __future__ import annotations

import contextlib
import importlib.abc
import importlib.machinery
import io
import sys

_WARP = "mujoco.mjx.warp"


class _QuietLoader(importlib.abc.Loader):
    def __init__(self, loader: importlib.abc.Loader):
        self._loader = loader

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module) -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            self._loader.exec_module(module)


class _QuietWarpFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name != _WARP:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is not None and spec.loader is not None:
            spec.loader = _QuietLoader(spec.loader)
        return spec


def install() -> None:
    """Silence MJX's Warp import messages (idempotent; a no-op once MJX is imported)."""
    if _WARP in sys.modules or any(isinstance(f, _QuietWarpFinder) for f in sys.meta_path):
        return
    sys.meta_path.insert(0, _QuietWarpFinder())
