"""Stage 2, ``features``: PCA (18) and RHF (300) features of every sample
(``relaff_jax.data.add_features`` with the perception of ``relaff_jax.perception``).

``add_features(tree, path, seed)`` attaches them to one dataset folder: what ``relaff
features`` calls, and what ``run(run, forced)`` calls for each dataset of the run folder with
the features seed from the run log. The chunk size comes from ``tree.dataset.feature_batch``
and the perception from ``tree.perception`` only."""
from __future__ import annotations

import functools
import time
from pathlib import Path
from typing import Any

from relaff_jax import data as D
from relaff_jax.config.perception import PerceptionConfig, stored_config
from relaff_jax.provenance import record_config
from relaff_jax.stages.protocol import Run, Status
from relaff_jax.sim import objects as lib
from relaff_jax.data.status import write_manifest
from relaff_jax.learn.datasets import fingerprint
from relaff_jax.sim.object_library import use_recorded, use_scene
from relaff_jax.data.store import read_sidecar
from relaff_jax.cluster import Remote

NAME = "features"


def default_feature_factory(seed: int, config: Any = None, objects: Any = None, action: Any = None):
    """``(compute_fn, config_dict)`` of the perception stage, as ``relaff features`` uses it.
    The object set the datasets' pairs come from is made active first (a cluster worker has
    only the built-ins active): ``objects`` (a ``sim.objects.ObjectSet``, e.g. a dataset's
    record) or the one ``action`` (an ``ActionConfig``) selects; neither: the active set."""
    # loaded when the stage runs: reproduce --status and the command's checks read this module
    from relaff_jax.perception import from_sim
    from relaff_jax.sim.world import build_world

    if objects is not None:
        lib.activate(objects)
    elif action is not None:
        use_scene(action.scene, action.grip_margin)
    cfg = config if config is not None else PerceptionConfig()
    return from_sim.make_feature_fn(build_world(), cfg, seed), feature_config(seed, cfg)


def feature_warmups(cfg: Any) -> list:
    """The features stage's perception programs compiled ahead (``perception.culled.warmups``)
    for a ``RunConfig``'s perception, with its action's object set active, as
    ``default_feature_factory`` builds the chain: functions of no argument that the generate
    stage runs on its background thread (``stages/generate.py``)."""
    import jax
    import numpy as np

    from relaff_jax.perception import culled, from_sim
    from relaff_jax.sim.world import build_world

    use_scene(cfg.action.scene, cfg.action.grip_margin)
    world = build_world()
    b = int(cfg.dataset.feature_batch)  # the stage's chunks are padded to this many scenes

    def geoms() -> None:
        """The scenes' geometry at the chunks' shape, on placeholder scenes: the camera's MJX
        model stack built (``World.model``, ~2 s) and the program traced and compiled here."""
        qpos = np.tile(np.asarray(world.mj_model.qpos0, np.float32), (b, 1))
        jax.block_until_ready(from_sim.jitted_geoms(world)(np.zeros(b, np.int32), qpos))

    return [*culled.warmups(world.mj_model.geom_type, world.geom_seg, cfg.perception, from_sim.SUB_BATCH), geoms]


def feature_config(seed: int, config: Any = None) -> dict:
    """The config dict ``default_feature_factory`` stores (without building the world)."""
    return {"perception": stored_config(config if config is not None else PerceptionConfig()), "seed": seed}


def add_features(tree: Any, path: Any, seed: int = 0, *, progress: bool = True, overwrite: bool = False,
                 client: Any = None, compute: tuple | None = None) -> dict:
    """The features stage on one dataset folder, as ``relaff features`` and ``reproduce`` run it:
    the simulated Kinect's PCA and RHF with the ``RunConfig`` ``tree``'s perception, in chunks
    of ``tree.dataset.feature_batch``, attached by ``data.add_features`` with this module's
    config record. ``client``: chunks as tasks on that cluster (each worker builds the
    perception once). ``compute``: ``(compute_fn, config_dict)`` already built (``reproduce``
    builds it once for every action, or takes a test's factory); default: the perception's."""
    objects = None
    if compute is None:  # the objects the dataset's pair indices refer to (the built-ins if it records none)
        objects = use_recorded(read_sidecar(Path(path)))
    if compute is None and client is None:
        compute = default_feature_factory(seed, tree.perception)
    elif compute is None:
        compute = Remote(default_feature_factory, seed, config=tree.perception, objects=objects, pick=0), \
            feature_config(seed, tree.perception)
    fn, config_dict = compute
    out = D.add_features(path, fn, tree.dataset.feature_batch, progress, config_dict, overwrite=overwrite,
                         client=client)
    record_config(path, tree, "features")  # the tree that made the folder, as every stage's folder holds it
    record_fingerprint(path)
    return out


def record_fingerprint(path: Any) -> None:
    """The dataset at ``path`` with finished features, loaded (every chunk verified) and
    fingerprinted as the experiment fingerprints its inputs (``learn.datasets.fingerprint``),
    recorded in its status manifest (``data.status.write_manifest``): a later status of the
    experiment reads the fingerprint instead of loading the dataset again."""
    d = D.load_dataset(path)
    if "pca" not in d:  # features not finished: nothing to fingerprint yet
        return
    spaces = ("pca", "rhf") if "rhf" in d else ("pca",)
    write_manifest(path, {s: v["x"] for s, v in fingerprint({"x": d}, spaces).items()})


def factories_for(cfg: Any):
    """``(feature_factory, feature_config)`` bound to a ``RunConfig``'s perception settings."""
    return (functools.partial(default_feature_factory, config=cfg.perception, action=cfg.action),
            functools.partial(feature_config, config=cfg.perception))


def action_status(run: Run, action: str) -> Status:
    if not run.paths.dataset(action).exists():  # nothing generated yet: nothing to featurise, not an error
        return Status("absent", "no dataset yet")
    want = run.feature_config(run.log["seeds"]["features"])
    return Status(*D.features_status(run.paths.dataset(action), run.cfg.dataset.feature_batch, want, verify=run.verify))


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
        # a forced stage recomputes whatever is there: its old chunks are not read (verified) first
        st = Status("absent", "forced") if forced else action_status(run, action)
        if st.state == "complete" and not forced:
            items[action] = {"status": "skipped"}
            continue
        t0 = time.perf_counter()
        if compute is None:
            compute, config_dict = run.feature_factory(fseed) if run.client is None else \
                (run.remote(run.feature_factory, fseed), run.feature_config(fseed))
        add_features(cfg, run.paths.dataset(action), fseed, progress=False, client=run.client,
                     overwrite=forced or st.state in ("stale", "corrupt"), compute=(compute, config_dict))
        dt = time.perf_counter() - t0
        items[action] = {"status": "ran", "seconds": round(dt, 2), "was": "forced" if forced else st.state}
        run.progress.message(f"features {action}: {cfg.dataset.n_samples} scenes in {dt:.0f} s")
    return items
