"""relaff_jax: relational affordances of object pairs, bootstrapped by transfer.

A vectorised JAX/MJX reimplementation of Fichtl et al., "Bootstrapping Relational
Affordances of Object Pairs using Transfer". One subpackage per stage, in pipeline order:

- ``sim``: the object library, one MJX world for every pair, scene sampling and settling,
  the 6-DOF arm, the nine motor programs and their physics labels, MuJoCo C references;
- ``data``: balanced, resumable datasets of labelled rollouts; export;
- ``perception``: the simulated Kinect, voxel grids, PCA and RHF features;
- ``learn``: the paper's forests, the bootstrapping protocol and sweeps, their analysis;
- ``report``: Table II, findings, figures, the report document;
- ``reproduce``: the whole study as one resumable command; ``cli``: the ``relaff`` command.

Shared by all: ``constants`` (actions, relations, segment codes), ``config`` (the one config
tree: every node, its checks, the presets and the random streams), ``stages`` (the four stages'
one contract), ``errors`` (``UserError``), ``io`` (atomic writes),
``provenance`` (versions, seeds).
"""
from __future__ import annotations

import os

# XLA:CPU's fusion emitters make MJX's kinematics cost grow exponentially with the depth of a
# kinematic chain (google-deepmind/mujoco#2957, jax-ml/jax#33761): a step of the 6-DOF arm
# world is 20-60x slower with them (docs/arm.md). The flag is read when JAX creates its CPU
# client, so it is set here, before any relaff_jax module runs a computation.
if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_use_fusion_emitters=false").strip()

from relaff_jax import quiet as _quiet  # noqa: E402

_quiet.install()  # MJX's "Failed to import warp" lines are noise on a CPU-only project

__version__ = "0.1.0"

# No subpackage is imported here: a command checks its input before JAX or MuJoCo load.
__all__ = ["load_dataset", "__version__"]


def load_dataset(path):
    """Load a dataset directory as named numpy arrays (see ``relaff_jax.data.load_dataset``)."""
    from .data import load_dataset as _load  # here: ``import relaff_jax`` sets the XLA flags, nothing more

    return _load(path)
