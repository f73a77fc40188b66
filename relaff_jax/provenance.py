"""What a run folder records about how it was made: package versions, the machine, seeds."""
from __future__ import annotations

import importlib.metadata
import os
import platform
from typing import Any

import numpy as np

PACKAGES = ("relaff_jax", "jax", "jaxlib", "mujoco", "mujoco-mjx", "numpy", "scikit-learn",
            "orbax-checkpoint", "matplotlib")


def versions() -> dict[str, str | None]:
    """Python and the versions of the packages that can change results (None: not installed)."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for pkg in PACKAGES:
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def machine() -> dict[str, Any]:
    """Platform, CPU architecture and core count (XLA's code, and so float rounding, depend on
    the CPU's features)."""
    return {"platform": platform.platform(), "machine": platform.machine(), "cpus": os.cpu_count()}


def derive_seed(*keys: int) -> int:
    """A 32-bit seed from integer keys: an independent stream per tuple of keys.

    ``derive_seed(run_seed, stage, index)`` never collides with another tuple's stream
    (``numpy.random.SeedSequence`` hashes the whole tuple).
    """
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0])
