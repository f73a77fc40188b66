"""Stage 1, ``generate``: one balanced dataset per action (``relaff_jax.data.generate_dataset``
with the simulation's ``make_rollout_fn``), in ``DIR/data/<action>/``.

``generate_one(tree, action, out, seed)`` makes one dataset folder: what ``relaff generate``
calls, and what ``run(run, forced)`` calls for each action of ``run.cfg.reproduce.actions``
with the action's seed from the run log. The sample count, chunk size and engine come from
``tree.dataset`` only."""
from __future__ import annotations

import functools
import importlib
import time
from pathlib import Path
from typing import Any

from relaff_jax import data as D
from relaff_jax import io as rio
from relaff_jax.data.layout import scheme_changes, selection_scheme
from relaff_jax.data.status import write_manifest
from relaff_jax.data.store import read_sidecar
from relaff_jax.provenance import record_config
from relaff_jax.stages.protocol import Run, ReproduceError, Status
from relaff_jax.config.action import ActionConfig
from relaff_jax.sim import object_library as ol
from relaff_jax.sim.actions import record as spec_record
from relaff_jax.stages import audits
from relaff_jax.sim.actions import record
from relaff_jax.cluster import cancel_all, nthreads, Remote

NAME = "generate"


def default_rollout_factory(action: str, batch: int, config: Any = None, engine: str = "mjx"):
    """``(rollout_fn, config_dict, object_names)`` of one action from ``relaff_jax.sim``
    (``config``: its ``ActionConfig``, default the paper's; ``engine``: "mjx" or "native", the
    executor of the motor programs; the rollouts carry object names)."""
    try:
        sim = importlib.import_module("relaff_jax.sim.rollouts")
    except ModuleNotFoundError as e:
        if e.name == "relaff_jax.sim.rollouts":
            raise ReproduceError(
                "the generate stage needs relaff_jax.sim.rollouts (the arm's nine motor programs that label the "
                "rollouts), which this installation does not have; the datasets cannot be generated") from e
        raise

    cfg = config if config is not None else ActionConfig()
    stored = {"action": action, "action_config": sim.stored_config(cfg)}
    objs = ol.use_scene(cfg.scene, cfg.grip_margin)
    if cfg.scene.library or cfg.scene.objects:  # the resolved objects, so the folder never depends on the file
        stored["objects"] = ol.record(objs)
    if spec_record(action) is not None:  # a user action: its spec's identity (a built-in's is the package's)
        stored["action_spec"] = spec_record(action)
    return sim.make_rollout_fn(action, batch, cfg, engine=engine), stored, None


def rollout_factory_for(cfg: Any):
    """The default factory bound to a ``RunConfig``'s action settings and engine."""
    return functools.partial(default_rollout_factory, config=cfg.action, engine=cfg.dataset.engine)


def _expected(run: Run, action: str) -> dict[str, Any]:
    return {"action": action, "n_samples": run.cfg.dataset.n_samples,
            "seed": run.log["seeds"]["datasets"][action], "batch": run.cfg.dataset.rollout_batch,
            "engine": run.cfg.dataset.engine}


def action_status(run: Run, action: str) -> Status:
    st = Status(*D.dataset_status(run.paths.dataset(action), _expected(run, action), verify=run.verify))
    if st.state != "complete":
        return st
    # the same rollouts selected under another scheme (a setting added since, e.g. dataset.unsettled):
    # not stale, the generate stage selects again from them (data.generate)
    changed = scheme_changes(read_sidecar(run.paths.dataset(action)).get("selection_scheme", {}),
                             selection_scheme(run.cfg.dataset))
    if changed:
        return Status("partial", f"selected with other settings ({', '.join(changed)}); to be selected again from its "
                                 "rollouts")
    return st


def status(run: Run) -> Status:
    return Status.combine({a: action_status(run, a) for a in run.cfg.reproduce.actions})


def progress(run: Run) -> float:
    acts = run.cfg.reproduce.actions
    return sum(D.generation_progress(run.paths.dataset(a), run.cfg.dataset.n_samples) for a in acts) / len(acts)


def generate_one(tree: Any, action: str, out: Any, seed: int, *, client: Any = None, progress: bool = False,
                 factory: Any = None, window: int | None = None) -> dict:
    """One action's dataset in ``out`` (created or resumed) from the config tree ``tree``: what
    ``relaff generate`` and ``reproduce`` both run. ``factory(action, batch) -> (rollout_fn,
    config_dict, object_names)`` defaults to the simulation bound to ``tree``
    (``rollout_factory_for``); with ``client`` the workers build (and compile) it themselves,
    once each. Returns ``data.generate_dataset``'s summary; writes ``out/relaff_config.json``."""
    factory = factory or rollout_factory_for(tree)
    batch = tree.dataset.rollout_batch
    fn, config_dict, names = factory(action, batch)
    if client is not None:
        fn = Remote(factory, action, batch, pick=0)
    summary = D.generate_dataset(out, action, fn, seed, config_dict, progress=progress,  # sizes: tree.dataset's
                                 dataset_config=tree.dataset, object_names=names, client=client, window=window)
    record_config(out, tree, "generate")  # the tree that made the folder, as every stage's folder holds it
    if read_sidecar(Path(out)).get("status") == "complete":
        write_manifest(out)  # later statuses answer from it while the folder is unchanged
    return summary


def _one(run: Run, action: str, window: int | None, beside: audits.Beside | None = None) -> dict:
    """Generate one action's dataset (resuming); what the run log records for it. Its audit is
    handed to ``beside`` (which the caller collects into ``item["audit"]``), or run here."""
    cfg = run.cfg
    t0 = time.perf_counter()
    s = generate_one(cfg, action, run.paths.dataset(action), run.log["seeds"]["datasets"][action], client=run.client,
                     factory=run.rollout_factory, window=window)
    dt = time.perf_counter() - t0
    item = {"status": "ran", "seconds": round(dt, 2), "rollouts": s["rollouts"],
            "new_rollouts": s["new_chunks"] * cfg.dataset.rollout_batch,
            "positive_rate": s["positive_rate"], "borrowed": s["borrowed"], "matching_met": s.get("matching_met")}
    extra = ""
    if s.get("discarded_chunks"):
        item["discarded_chunks"] = s["discarded_chunks"]
        extra = f"; {s['discarded_chunks']} chunks simulated past the stopping point discarded"
    if s.get("matching_met") is False:
        extra += f"; distance matching NOT met ({s['borrowed']} negatives borrowed)"
    run.progress.message(f"generate {action}: {cfg.dataset.n_samples} samples from {s['rollouts']} rollouts "
                         f"(positive rate {s['positive_rate']:.1%}) in {dt:.0f} s{extra}")
    if beside is not None:
        beside.submit(action)
    else:
        item["audit"] = audit_one(run, action)
    return item


def audit_one(run: Run, action: str) -> dict:
    """The physics audit of one finished dataset (``data.audit.ensure_audit``: a MuJoCo C
    replay of ``DEFAULT_SAMPLE`` of its rollouts, stored as ``audit.json``; a stored one is
    reused), here and now; what the run log records of it. A dataset the audit cannot replay (no
    recorded action config or simulation fields) is recorded as not audited. The stage itself
    audits each dataset beside the next action's generation (``stages/audits.py``)."""
    return audits.record(run, action, *audits.audit(run.paths.dataset(action)))


def run(run: Run, forced: bool) -> dict:
    """Every action's dataset: one after another, or on a cluster all at once (one driver
    thread per action, the cluster's task slots shared between them, so that a few chunks per
    action keep many workers busy and each action overshoots its stopping point by little)."""
    cfg, paths = run.cfg, run.paths
    if forced:
        rio.remove_tree(paths.data)
    acts = cfg.reproduce.actions
    # loaded when the stage runs: reproduce --status and the command's checks read this module
    from relaff_jax.sim.actions.check import check_actions

    check_actions(acts, cfg.action)  # a user action's rules traced once, before any simulation
    users = [a for a in acts if record(a) is not None]
    if users and run.client is not None:
        raise ReproduceError(f"--cluster: the user actions {users} run only here (the cluster's workers do not "
                             "load --plugins files)")
    items: dict[str, Any] = {}
    todo = []
    for action in acts:
        st = action_status(run, action)
        if st.state == "complete":
            items[action] = {"status": "skipped"}
        elif st.state in ("stale", "corrupt"):
            raise ReproduceError(f"{paths.dataset(action)}: {st.why}; redo this dataset alone with --redo-dataset "
                                 f"{action} (the other datasets are kept), or all of them with --force generate")
        else:
            todo.append(action)
    if run.client is None or len(todo) < 2:
        with audits.Beside(run) as beside:  # each audit beside the next action's generation
            if todo and beside.pool is not None and getattr(run.rollout_factory, "func", None) is default_rollout_factory:
                from relaff_jax.sim.warm import planner_warmups  # the simulation loads when the stage runs

                beside.warm(planner_warmups(cfg.action, cfg.dataset.rollout_batch, todo))
            from relaff_jax.stages.features import default_feature_factory, feature_warmups

            if todo and beside.pool is not None and getattr(run.feature_factory, "func", None) is default_feature_factory:
                # the features stage's programs, compiled while the physics runs (XLA's compiles leave the GIL free)
                beside.warm(feature_warmups(cfg))
            if todo and cfg.experiment.forest.engine == "compiled":  # the experiment's kernels, compiled or loaded
                from relaff_jax.learn.forest.compiled.forest import warm

                beside.warm_elsewhere(warm, cfg.experiment.forest)
            if todo:  # the report's compiled mix of candidates, compiled or loaded in the same process
                from relaff_jax.learn.measures import compile_mix_kernel

                beside.warm_elsewhere(compile_mix_kernel)
            for action in todo:
                run.progress.set(f"{action} ({acts.index(action) + 1}/{len(acts)})")
                items[action] = _one(run, action, None, beside)
            if todo:
                run.progress.set("the last physics audits")
            for action, a in beside.finish().items():
                items[action]["audit"] = a
        return dict(sorted(items.items(), key=lambda kv: acts.index(kv[0])))
    from concurrent.futures import ThreadPoolExecutor

    window = max(1, -(-nthreads(run.client) // len(todo)))
    run.progress.set(f"{len(todo)} actions at once on the cluster")
    with ThreadPoolExecutor(len(todo), thread_name_prefix="generate") as pool:
        futures = {a: pool.submit(_one, run, a, window) for a in todo}
        try:
            for a in todo:
                items[a] = futures[a].result()
        except BaseException:
            # stop the other actions too: their pending tasks are cancelled, their drivers unwind
            # (chunks already written are kept for the rerun)
            cancel_all(run.client)
            raise
    return dict(sorted(items.items(), key=lambda kv: acts.index(kv[0])))


