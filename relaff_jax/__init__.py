"""relaff_jax: relational affordances of object pairs, bootstrapped by transfer.

A vectorised JAX/MJX reimplementation of Fichtl et al., "Bootstrapping Relational
Affordances of Object Pairs using Transfer". Stages (one module each):
``objects`` (the 29-object library) -> ``world`` (one MJX model for every pair) ->
``scenes`` (sampling, settling, relations) -> ``actions`` (arm, motor programs, labels) ->
``dataset`` (balanced, resumable datasets) -> ``perception`` (Kinect, PCA, RHF) ->
``learning`` / ``experiment`` / ``report`` (forests, bootstrapping, Table II).
"""
from __future__ import annotations

import os

# XLA:CPU's fusion emitters make MJX's kinematics cost grow exponentially with the depth of a
# kinematic chain (google-deepmind/mujoco#2957, jax-ml/jax#33761): a step of the 6-DOF arm
# world is 20-60x slower with them (docs/arm.md). The flag is read when JAX creates its CPU
# client, so it is set here, before any relaff_jax module runs a computation.
if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_use_fusion_emitters=false").strip()

__version__ = "0.1.0"

# Light re-exports; heavy modules (JAX, MuJoCo) load on first use.
__all__ = ["load_dataset", "__version__"]


def load_dataset(path):
    """Load a dataset directory as named numpy arrays (see ``relaff_jax.dataset.load_dataset``)."""
    from .dataset import load_dataset as _load

    return _load(path)
