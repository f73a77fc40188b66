"""Numpy stand-ins for the simulation and the perception (not physics): rollouts drawn from
the chunk's key, features drawn from the rollout index. "beside" scenes are far apart and
rarely positive, stacked ones close and mostly positive (the regime of the paper's distance
matching). The driver tests (reproduce, cluster, dataset, export) run the real stages on
them in seconds; they check the plumbing, not any result.

Module-level functions, so that a Dask worker or a subprocess imports them by reference."""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from relaff_jax import data as ds
from relaff_jax.constants import ACTIONS
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.stages.protocol import Hooks

FEATURE_CONFIG = {"kind": "numpy stand-in"}
# the tiny preset, smaller still: 4-tree forests, two sizes, no example scenes (the stand-in
# rollouts have no scene to draw); callers add ``reproduce.actions``
SMALL_RUN = {"dataset.n_samples": 32, "experiment.forest.base_trees": 4, "experiment.forest.max_trees": 4,
             "experiment.sizes": (4, 10), "reproduce.examples_per_action": 0}
BUILDS = {"n": 0}  # rollout/feature functions built in this process (on a Dask worker: by its tasks)


def builds() -> int:
    return BUILDS["n"]


def rollout_factory(action, batch, stop_after=None, delay=0.0):
    """The simulation's factory signature ``(action, batch) -> (fn, config, scene)``; ``fn(key,
    b)`` draws from ``key`` and the action's index (same key, same bits). ``stop_after`` calls
    raise KeyboardInterrupt (what Ctrl-C does mid-stage); ``delay`` seconds per call."""
    BUILDS["n"] += 1
    calls = [0]

    def fn(key, b):
        calls[0] += 1
        if stop_after is not None and calls[0] > stop_after:
            raise KeyboardInterrupt
        time.sleep(delay)
        rng = np.random.default_rng(np.asarray(key).tolist() + [ACTIONS.index(action)])
        rel = rng.integers(0, 3, b)
        dist = np.where(rel == 0, rng.uniform(0.1, 1.2, b), rng.uniform(0.03, 0.2, b))
        return {"label": rng.random(b) < np.where(rel == 0, 0.25, 0.75),
                "relation": rel.astype(np.int32), "cog_distance": dist.astype(np.float32),
                "toy": np.asarray(("ball", "cube"))[rng.integers(0, 2, b)],
                "other": np.asarray(("plate", "cup"))[rng.integers(0, 2, b)]}

    return fn, {"stand_in": action}, None


def feature_config(seed):
    return dict(FEATURE_CONFIG, seed=seed)


def feature_factory(seed):
    """The perception's factory signature ``seed -> (compute, config)``; column 9 of the PCA
    features carries the distance and the label (something learnable)."""
    BUILDS["n"] += 1

    def compute(s):
        rng = np.random.default_rng([seed, int(s["rollout"][0])])
        n = len(s["label"])
        pca = rng.normal(size=(n, 18)).astype(np.float32)
        pca[:, 9] = s["cog_distance"] + 0.3 * s["label"]
        return {"pca": pca, "rhf": rng.random((n, 300)).astype(np.float32), "unseen": np.zeros((n, 2), bool)}

    return compute, feature_config(seed)


# the hooks `reproduce()` takes in place of the simulation and the perception
HOOKS = Hooks(rollout_factory=rollout_factory, feature_factory=feature_factory, feature_config=feature_config)


# ---- the dataset layer's own stand-ins (tests/data): relation names, scene fields, kills


class Killed(Exception):
    """What the dataset stand-ins raise to simulate a kill mid-stage."""


DATASET_TOYS = ("ball", "cube")
DATASET_OTHERS = ("plate", "cup", "box")
ACTION_CFG = {"physics": {"dt": 0.002}, "lift_height": 0.05}


def synthetic_rollout_fn(kill_after: int | None = None, all_negative: bool = False, calls: list | None = None):
    """``fn(key, b)`` drawing from ``key`` alone, with every field a dataset stores (relation
    names, qpos, pair, sample seed); raises ``Killed`` after ``kill_after`` calls; appends each
    key to ``calls``."""
    calls = [] if calls is None else calls

    def rollout_fn(key, b):
        if kill_after is not None and len(calls) >= kill_after:
            raise Killed("simulated kill")
        calls.append(np.asarray(key).tolist())
        rng = np.random.default_rng(np.asarray(key).tolist())
        rel = rng.integers(0, 3, b)
        dist = np.where(rel == 0, rng.uniform(0.1, 1.2, b), rng.uniform(0.03, 0.2, b))
        p = np.where(rel == 0, 0.15, 0.8)
        label = (rng.random(b) < p) & (not all_negative)
        return {
            "label": label,
            "relation": np.asarray(ds.RELATIONS)[rel],
            "cog_distance": dist.astype(np.float32),
            "toy": np.asarray(DATASET_TOYS)[rng.integers(0, 2, b)],
            "other": np.asarray(DATASET_OTHERS)[rng.integers(0, 3, b)],
            "qpos": rng.normal(size=(b, 2, 7)).astype(np.float32),
            "pair": rng.integers(0, 6, b).astype(np.int32),
            "sample_seed": rng.integers(0, 2**31, b).astype(np.uint32),
        }

    return rollout_fn


EXACT = DatasetConfig(max_rollouts=2000, distance_bins=8, borrow_fraction=0.0)  # no borrowing


def gen(path, n=40, seed=3, batch=16, fn=None, **kw):
    """A lift dataset of ``n`` samples in chunks of ``batch`` from ``synthetic_rollout_fn`` (exact
    matching by default): ``n`` and ``batch`` set the dataset node's ``n_samples`` and ``rollout_batch``."""
    dcfg = dataclasses.replace(kw.pop("dataset_config", EXACT), n_samples=n, rollout_batch=batch)
    return ds.generate_dataset(path, "lift", fn or synthetic_rollout_fn(), seed, ACTION_CFG,
                               progress=False, dataset_config=dcfg, **kw)


def feature_fn(kill_after: int | None = None, sizes: list | None = None):
    """Deterministic features of a sample batch (no draws): PCA columns are multiples of the
    distance, RHF the rollout index mod 7; records batch sizes in ``sizes``; raises ``Killed``
    after ``kill_after`` batches."""
    sizes = [] if sizes is None else sizes

    def compute(s):
        if kill_after is not None and len(sizes) >= kill_after:
            raise Killed("simulated kill")
        sizes.append(len(s["label"]))
        d = s["cog_distance"].astype(np.float64)
        pca = np.stack([d * (i + 1) for i in range(18)], axis=1).astype(np.float32)
        rhf = np.tile(s["rollout"][:, None] % 7, (1, 300)).astype(np.float32)
        unseen = np.stack([s["rollout"] % 5 == 0, s["toy"] == "cube"], axis=1)
        return {"pca": pca, "rhf": rhf, "unseen": unseen}

    return compute


def run(out, actions, seed=3, **kw):
    """`reproduce()` of the tiny preset made smaller (``SMALL_RUN``) on ``actions``, with the
    stand-ins in place of the simulation and the perception; ``kw`` overrides any argument
    (``rollout_factory=``: these hooks with another rollout stand-in)."""
    from relaff_jax import reproduce as R

    hooks = kw.pop("hooks", HOOKS)
    if "rollout_factory" in kw:
        hooks = dataclasses.replace(hooks, rollout_factory=kw.pop("rollout_factory"))
    args = dict(hooks=hooks, overrides=dict(SMALL_RUN, **{"reproduce.actions": tuple(actions)}), jobs=1, progress=False)
    args.update(kw)
    return R.reproduce(out, "tiny", seed, **args)
