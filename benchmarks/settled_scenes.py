"""The settled scenes the perception benchmarks measure on, and their shared options.

``perception_culled.py`` and ``perception_stages.py`` both take ``--actions``, ``--scenes`` and
``--seed`` (``add_scene_args``) and run on the same scenes (``load_scenes``): ``--scenes`` per
action, sampled and settled as the generate stage does (``scenes.sample_pairs`` + place,
MuJoCo C settle), in chunks of 32 (the paper preset's ``feature_batch``) with rollout ids as in
a dataset. Imported by the scripts (``python benchmarks/X.py`` puts this folder on the path).
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

import relaff_jax  # noqa: F401  (XLA flags before JAX work)
from relaff_jax.sim import rollouts, templates
from relaff_jax.sim import scenes as sc
from relaff_jax.sim import world as wd
from relaff_jax.sim.native import settle as native_settle
from relaff_jax.sim.native.batch import default_threads


def add_scene_args(ap: argparse.ArgumentParser, scenes: int) -> argparse.ArgumentParser:
    """``--actions``, ``--scenes`` (default ``scenes`` per action) and ``--seed`` on ``ap``."""
    ap.add_argument("--actions", nargs="+", default=["lift", "take", "pour"])
    ap.add_argument("--scenes", type=int, default=scenes, help="scenes per action (a multiple of 32)")
    ap.add_argument("--seed", type=int, default=0)
    return ap


def machine_line() -> str:
    """The header line: machine, cores, jax, load average before, the time (UTC)."""
    return (f"machine: {platform.machine()}, {os.cpu_count()} cores; jax {jax.__version__}; load average before "
            f"{os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")


def settled_chunks(sw, action: str, n: int, seed: int, first_id: int) -> list[dict]:
    """n settled scenes of ``action``'s pairs in chunks of 32 (``pair``, ``qpos_settled``, ``rollout_id``)."""
    cfg = templates.ActionConfig()
    place_fn, _, _ = sc.jitted_scene_fns(sw, cfg.scene)
    kp, kq = jax.random.split(jax.random.PRNGKey(seed))
    pair = np.asarray(sc.sample_pairs(kp, rollouts.allowed_pairs(sw, action), sw, n))
    q0, it = jax.device_get(place_fn(kq, jnp.asarray(pair)))
    s = native_settle.settle_batch(sw, pair, q0, it, cfg.scene, default_threads())
    ids = np.arange(n, dtype=np.int64) + first_id
    q = np.asarray(s.qpos)
    return [{"pair": pair[lo:lo + 32], "qpos_settled": q[lo:lo + 32], "rollout_id": ids[lo:lo + 32]}
            for lo in range(0, n, 32)]


def load_scenes(args: argparse.Namespace) -> tuple:
    """``(sw, chunks)``: the paper's world and ``args.scenes`` settled scenes of each of
    ``args.actions`` (action i: seed ``args.seed + 10 i``, rollout ids from ``2**33 + i * scenes``)."""
    sw = wd.build_world(templates.ActionConfig().phys)
    chunks = []
    for i, a in enumerate(args.actions):
        chunks += settled_chunks(sw, a, args.scenes, args.seed + 10 * i, 2**33 + i * args.scenes)
    return sw, chunks
