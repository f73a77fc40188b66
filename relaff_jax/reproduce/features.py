"""Stage 2, ``features``: PCA (18) and RHF (300) features of every sample
(``relaff_jax.data.add_features`` with the perception of ``relaff_jax.perception``)."""
from __future__ import annotations

import functools
import time
from typing import Any

from relaff_jax import data as D
from relaff_jax.reproduce.stage import Run, Status

NAME = "features"


def default_feature_factory(seed: int, config: Any = None):
    """``(compute_fn, config_dict)`` of the perception stage, as ``relaff features`` uses it."""
    from relaff_jax import perception as pc
    from relaff_jax.perception import from_sim
    from relaff_jax.sim import build_world

    cfg = config if config is not None else pc.PerceptionConfig()
    return from_sim.make_feature_fn(build_world(), cfg, seed), feature_config(seed, cfg)


def feature_config(seed: int, config: Any = None) -> dict:
    """The config dict ``default_feature_factory`` stores (without building the world)."""
    from relaff_jax import perception as pc

    return {"perception": pc.stored_config(config if config is not None else pc.PerceptionConfig()), "seed": seed}


def add_features(path: Any, batch: int, seed: int = 0, config: Any = None, *, progress: bool = True,
                 overwrite: bool = False, client: Any = None) -> dict:
    """The features stage on one dataset folder, as ``relaff features`` and tests run it: the
    simulated Kinect's PCA and RHF (``config``: a ``PerceptionConfig``, default the paper's)
    attached by ``data.add_features`` with the config record this module writes for
    ``reproduce`` too. ``client``: chunks as tasks on that cluster (each worker builds the
    perception once)."""
    if client is None:
        fn = default_feature_factory(seed, config)[0]
    else:
        from relaff_jax.cluster import Remote

        fn = Remote(default_feature_factory, seed, config=config, pick=0)
    return D.add_features(path, fn, batch, progress, feature_config(seed, config), overwrite=overwrite, client=client)


def factories_for(cfg: Any):
    """``(feature_factory, feature_config)`` bound to a ``RunConfig``'s perception settings."""
    return (functools.partial(default_feature_factory, config=cfg.perception),
            functools.partial(feature_config, config=cfg.perception))


def action_status(run: Run, action: str) -> Status:
    want = run.feature_config(run.log["seeds"]["features"])
    return Status(*D.features_status(run.paths.dataset(action), run.cfg.dataset.feature_batch, want))


def status(run: Run) -> Status:
    return Status.combine({a: action_status(run, a) for a in run.cfg.reproduce.actions})


def progress(run: Run) -> float:
    acts, d = run.cfg.reproduce.actions, run.cfg.dataset
    return sum(D.features_progress(run.paths.dataset(a), d.n_samples, d.feature_batch) for a in acts) / len(acts)


def run(run: Run, forced: bool) -> dict:
    cfg = run.cfg
    fseed = run.log["seeds"]["features"]
    acts = cfg.reproduce.actions
    items: dict[str, Any] = {}
    compute = None
    for i, action in enumerate(acts):
        run.progress.set(f"{action} ({i + 1}/{len(acts)})")
        st = action_status(run, action)
        if st.state == "complete" and not forced:
            items[action] = {"status": "skipped"}
            continue
        t0 = time.perf_counter()
        if compute is None:
            compute, config_dict = run.feature_factory(fseed) if run.client is None else \
                (run.remote(run.feature_factory, fseed), run.feature_config(fseed))
        D.add_features(run.paths.dataset(action), compute, cfg.dataset.feature_batch, False, config_dict,
                       overwrite=forced or st.state in ("stale", "corrupt"), client=run.client)
        dt = time.perf_counter() - t0
        items[action] = {"status": "ran", "seconds": round(dt, 2), "was": st.state}
        run.progress.message(f"features {action}: {cfg.dataset.n_samples} scenes in {dt:.0f} s")
    return items
