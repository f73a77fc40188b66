"""The sweep of paper section V: every condition, size and repetition of one or both spaces.

Takes ``{action: dataset}`` (``load_datasets`` or ``synthetic_datasets``), an output folder,
the config, the spaces and the seed; ``run_experiment`` writes ``out/experiment.json``
(config, seed, actions, data fingerprint) and per space ``out/<space>/prep.npz``, the
finished blocks ``out/<space>/blocks/*.npz`` and ``out/<space>/results.npz`` with the
accuracies ``acc: (target, condition, size, rep)``, and returns the results paths. A rerun
resumes from the finished blocks; another config, seed or data in the same folder is refused.

Protocol (docs/learning.md has the full story):

1. Pools, once per seed and action (``protocol.split_pools``): a *source pool* (trains the
   action's source predictor and categories), ``corr_scenes`` held-out scenes for the
   correlation heuristic, and a disjoint *target pool*.
2. Prep, once per seed and space (``prep.prepare``): source predictors, categories, their
   outputs on every target pool, the correlation matrix.
3. Sweep, one block per (target, repetition, chunk of sizes) (``blocks.block_outcomes``):
   each target has one test set (``draws.draw_test``: balanced by class by default, the same
   for every repetition and both spaces); each repetition draws a training order from the
   rest of the pool (``draws.draw_train``) and size n trains on its first n (nested training
   sets, shared by every condition: paired comparisons). At ``select_size`` every DB1 and CB1
   candidate also gets its leave-one-out accuracy (the online "best after ten").
   Repetitions are the outer loop, so early blocks are representative for the ETA.

``results.npz`` holds ``acc: (A, C, S, R)``, ``loo: (A, C, R)`` and, with
``keep_outcomes``, every test scene's outcome ``correct: (A, C, S, R, ceil(T/8))`` bit-packed
along the scenes (``n_test: (A,)`` scenes per target).
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import to_dict
from relaff_jax.constants import SPACES
from relaff_jax.sim.actions.registry import action_id, record as action_record  # noqa: E402 (the run's actions; no JAX)
from relaff_jax.errors import UserError
from relaff_jax.learn import folder as L
from relaff_jax.learn import reuse as reuse_mod
from relaff_jax.learn import user_conditions
from relaff_jax.learn.blocks import SUBSETS, BlockJob, Target, read_block, run_block_job
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn.checks import check_config
from relaff_jax.learn.datasets import check_datasets, fingerprint
from relaff_jax.learn.draws import draw_rep
from relaff_jax.learn.learners import learner_of
from relaff_jax.learn.parallel import run_parallel
from relaff_jax.learn.prep import prepare
from relaff_jax.learn.protocol import (
    pool_sizes,
    split_pools,
    block_fits,
    category_allowed,
    category_masks,
    condition_names,
    condition_plan,
    layout,
    loo_conditions,
    condition_repeats,
)
from relaff_jax.learn.results import FORMAT_VERSION
from relaff_jax.learn.states import state_features
from relaff_jax.config import streams


def run_experiment(datasets: Mapping[str, Mapping[str, Any]], out: str | os.PathLike, cfg: ExperimentConfig,
                   spaces: Sequence[str] = SPACES, seed: int = 0, jobs: int = 1, progress: bool = True,
                   data_desc: Sequence[str] = (), client: Any = None,
                   reuse: str | os.PathLike | None = None) -> dict[str, Path]:
    """Run (or resume) the protocol; write ``out/<space>/results.npz``; return their paths.

    ``out/experiment.json`` records config, seed, actions and a data fingerprint; resuming
    with different ones is an error (start a new ``out`` instead). ``reuse``: another
    reading's experiment folder whose unchanged conditions are read, not refitted
    (``learn.reuse``: the same bits).
    """
    check_config(cfg)
    spaces = list(dict.fromkeys(spaces))
    for s in spaces:
        if s not in SPACES:
            raise UserError(f"unknown space {s!r}; expected one of {SPACES}")
    actions = check_datasets(datasets, spaces)
    for a in actions:  # every action's pools fit its data: refused before experiment.json is written
        split_pools(len(datasets[a]["label"]), action_id(a), cfg, seed)
    out = Path(out)
    meta: dict[str, Any] = {
        "format": FORMAT_VERSION,
        "config": to_dict(cfg),
        "seed": int(seed),
        "actions": actions,
        "spaces": spaces,
        "fingerprint": fingerprint(datasets, spaces),
        "plugins": user_conditions.record(cfg),  # the user's conditions: origin and sha256 of their source
    }
    specs = {a: action_record(a) for a in actions if action_record(a) is not None}
    if specs:  # a user action's spec (its datasets record it too); none for the nine
        meta["action_specs"] = specs
    donor = reuse_mod.open_donor(reuse, out, meta, cfg) if reuse is not None else None
    meta_path = L.meta(out)
    if meta_path.exists():
        # same protocol, seed, actions and data; a space may be added to a finished one
        old = rio.read_json(meta_path)
        now = rio.jsonable(meta)
        # the forest engine, and settings only the analysis reads added after a run began, do
        # not make it another run (config.result_differences)
        diff = L.meta_differences(old, now, cfg)
        if diff:
            raise UserError(f"{out} holds an experiment with different {diff}; use a new --out to start another")
        if set(spaces) - set(old["spaces"]):
            old["spaces"] = [s for s in SPACES if s in set(old["spaces"]) | set(spaces)]
            old["fingerprint"] = dict(old["fingerprint"], **now["fingerprint"])
            rio.atomic_write_json(meta_path, old)
    else:
        # the pools' real sizes (a preset may shrink them to the data), for the report's protocol table
        pools = {a: dict(zip(("source", "corr", "test"), pool_sizes(len(datasets[a]["label"]), cfg))) for a in actions}
        reused = {"reused_from": str(donor.out.resolve())} if donor else {}
        rio.atomic_write_json(meta_path, dict(meta, data=list(map(str, data_desc)), pool_sizes=pools,
                                              started=time.strftime("%Y-%m-%d %H:%M:%S"), **reused))
    paths = {}
    for space in spaces:
        paths[space] = run_space(datasets, L.space_dir(out, space), cfg, space, actions, seed, jobs, progress, client,
                                 donor if donor and space in donor.spaces else None)
    return paths


def run_space(datasets: Mapping[str, Mapping[str, Any]], sdir: Path, cfg: ExperimentConfig, space: str,
              actions: list[str], seed: int, jobs: int, progress: bool, client: Any = None,
              donor: reuse_mod.Donor | None = None) -> Path:
    """One space of ``run_experiment`` in ``sdir``: prep (reused if saved), every block not yet
    on disk, then ``sdir/results.npz``; returns its path. ``client``: run the forests as tasks
    on that Dask cluster (the same bits). ``donor``: another reading's folder giving the prep
    and every condition whose learner is unchanged (``learn.reuse``)."""
    t0 = time.perf_counter()
    prep_path = sdir / L.PREP
    dsdir = L.space_dir(donor.out, space) if donor else None
    if donor and not prep_path.exists() and (dsdir / L.PREP).exists():
        rio.atomic_write_bytes(prep_path, (dsdir / L.PREP).read_bytes())  # it reads no key the readings differ in
    if prep_path.exists():
        with np.load(prep_path) as z:
            prep = {k: z[k] for k in z.files}
    else:
        prep = prepare(datasets, space, cfg, seed, jobs, progress, client)
        rio.atomic_save_npz(prep_path, **prep)
    t_prep = time.perf_counter() - t0
    a, sizes, reps = len(actions), list(cfg.sizes), cfg.reps(space)
    n_cond = layout(a, len(cfg.thresholds))["n"]
    chunks = [sizes[i : i + cfg.sizes_per_block] for i in range(0, len(sizes), cfg.sizes_per_block)]
    corr = prep["corr"]
    # the user's conditions (conditions.py) after the built-ins on the condition axis
    ext = user_conditions.extend({t: _states(datasets[t], prep[f"target:{t}"], t, space, cfg) for t in actions}
                                 if user_conditions.custom_names(cfg, space) else {}, prep, actions, cfg, space,
                                 category_allowed(actions, cfg), n_cond)
    n_cond += len(ext.names)
    plans = [condition_plan(actions, ti, corr, cfg, space) + ext.plans.get(t, []) for ti, t in enumerate(actions)]
    reps_of = [{**condition_repeats(p, cfg, space, a), **{c: 1 for c, _ in ext.plans.get(t, [])}}
               for p, t in zip(plans, actions)]  # per condition (DBn's may differ; a user's: 1)
    loo_conds = loo_conditions(a, len(cfg.thresholds))
    if donor:  # per target, the conditions the donor's blocks cannot give
        dplans = [condition_plan(actions, ti, corr, donor.cfg, space) + ext.plans.get(t, []) for ti, t in enumerate(actions)]
        refits = [reuse_mod.refit(p, r, dp, {**condition_repeats(dp, donor.cfg, space, a),
                                             **{c: 1 for c, _ in ext.plans.get(t, [])}}, loo_conds)
                  for p, r, dp, t in zip(plans, reps_of, dplans, actions)]
    acc = np.full((a, n_cond, len(sizes), reps), np.nan)
    loo = np.full((a, n_cond, reps), np.nan)
    loo_n = cfg.select_size if cfg.online_select else 0
    labels_of = {t: np.asarray(datasets[t]["label"]).astype(bool)[prep[f"target:{t}"]] for t in actions}
    tests = {t: draw_rep(labels_of[t], int(prep[f"test_size:{t}"]), max(sizes), seed, action_id(t), 0,
                         cfg.balanced_test, cfg.balanced_train)[0] for t in actions}
    n_test = np.asarray([len(tests[t]) if cfg.keep_outcomes else 0 for t in actions])
    # the outcomes bit-packed along the scenes as the blocks give them (a target with fewer
    # test scenes than the most is zero-padded: the bytes np.packbits gives the padded bools)
    correct = np.zeros((a, n_cond, len(sizes), reps, (int(n_test.max()) + 7) // 8), np.uint8)
    subsets = {t: subset_codes(datasets[t], prep[f"target:{t}"][tests[t]]) for t in actions}
    acc_subset = np.full((a, n_cond, len(sizes), reps, len(SUBSETS)), np.nan)
    calls, weights, done_fits, total_fits = [], [], 0, 0
    keys = []
    target_data: dict[str, Target] = {}  # per target, built once, shared by all its blocks
    for r in range(reps):  # repetitions outermost: early blocks are representative for the ETA
        for ti, t in enumerate(actions):
            pool = prep[f"target:{t}"]
            draws = None
            for ci, chunk in enumerate(chunks):
                path = L.block(sdir, t, r, ci)
                fits = block_fits(plans[ti], len(chunk), loo_n if loo_n in chunk else 0, loo_conds, reps_of[ti])
                total_fits += fits
                s0 = sizes.index(chunk[0])
                got = read_block(path, n_cond, chunk, packed=True)
                if got is not None and got["n_test"] == n_test[ti]:
                    _store(acc, correct, loo, acc_subset, got, ti, s0, len(chunk), r)
                    done_fits += fits
                    continue
                dpath = L.block(dsdir, t, r, ci) if donor else None
                dgot = read_block(dpath, n_cond, chunk, packed=True) if donor else None
                if dgot is not None and dgot["n_test"] != n_test[ti]:
                    dgot = None
                if dgot is not None and not refits[ti]:  # nothing changed: the donor's block is this one
                    rio.atomic_write_bytes(path, dpath.read_bytes())
                    _store(acc, correct, loo, acc_subset, dgot, ti, s0, len(chunk), r)
                    total_fits -= fits
                    continue
                only = refits[ti] if dgot is not None else None
                if only is not None:  # the fits this block still makes
                    total_fits -= fits
                    fits = block_fits([pc for pc in plans[ti] if pc[0] in only], len(chunk),
                                      loo_n if loo_n in chunk else 0, loo_conds, reps_of[ti])
                    total_fits += fits
                if t not in target_data:
                    ds = datasets[t]
                    target_data[t] = Target(_states(ds, pool, t, space, cfg), np.asarray(ds["label"]).astype(bool)[pool],
                                            ext.boot(t, prep[f"boot:{t}"]))
                if draws is None:
                    draws = draw_rep(labels_of[t], int(prep[f"test_size:{t}"]), max(sizes), seed, action_id(t), r,
                                     cfg.balanced_test, cfg.balanced_train)
                test_idx, train_order = draws
                job = BlockJob(path=str(path), plan=plans[ti], train_order=train_order, test_idx=test_idx, sizes=chunk,
                               repeats=reps_of[ti], n_conditions=n_cond, learner=learner_of(cfg),
                               seed_keys=(seed, streams.SWEEP_FOREST, streams.SPACE_CODE[space], action_id(t), r), loo_size=loo_n or None,
                               loo_conditions=loo_conds, keep_outcomes=cfg.keep_outcomes, subset=subsets[t],
                               only=only, donor=None if only is None else str(dpath))
                calls.append((run_block_job, (target_data[t], job), {}))
                weights.append(fits)
                keys.append((ti, s0, len(chunk), r))
    results = run_parallel(calls, jobs, progress, total=total_fits, desc=f"{space} sweep", unit="fit",
                            weights=weights, initial=done_fits, client=client)
    for (ti, s0, n, r), got in zip(keys, results):
        _store(acc, correct, loo, acc_subset, got, ti, s0, n, r)
    masks = category_masks(corr, actions, cfg)
    res_path = sdir / L.RESULTS
    rio.atomic_save_npz(
        res_path,
        acc=acc,
        sizes=np.asarray(sizes),
        actions=np.asarray(actions),
        conditions=np.asarray(condition_names(actions, cfg.thresholds) + ext.names),
        thresholds=np.asarray(cfg.thresholds, dtype=float),
        corr=corr,
        category_masks=masks,
        test_size=np.asarray([len(tests[t]) for t in actions]),
        test_positive=np.asarray([int(labels_of[t][tests[t]].sum()) for t in actions]),
        loo=loo,
        acc_subset=acc_subset,
        subset_count=np.stack([np.bincount(subsets[t][subsets[t] >= 0], minlength=len(SUBSETS)) for t in actions]),
        corr_feasible=prep["corr_feasible"],
        corr_stacked=prep["corr_stacked"],
        correct=correct,
        n_test=n_test,
        seconds=np.asarray(time.perf_counter() - t0),
        seconds_prep=np.asarray(t_prep),
        new_fits=np.asarray(sum(weights)),
    )
    return res_path


def _states(ds: Mapping[str, Any], pool: np.ndarray, t: str, space: str, cfg: ExperimentConfig) -> np.ndarray:
    """``(M, D)`` the states of target ``t``'s pool scenes in ``space``."""
    return state_features(np.asarray(ds["pca"])[pool], np.asarray(ds["rhf"])[pool] if space == "rhf" else None, t, space,
                          cfg.state)


def subset_codes(ds: Mapping[str, Any], idx: np.ndarray) -> np.ndarray:
    """``(T,)`` codes into ``blocks.SUBSETS`` of the test scenes ``idx`` of a dataset: 0
    positive, 1 feasible negative, 2 infeasible negative (-1: a negative of a dataset without
    the ``feasible`` field)."""
    label = np.asarray(ds["label"]).astype(bool)[idx]
    if "feasible" not in ds:
        return np.where(label, 0, -1)
    feasible = np.asarray(ds["feasible"]).astype(bool)[idx]
    return np.where(label, 0, np.where(feasible, 1, 2))


def _store(acc, correct, loo, acc_subset, got, ti, s0, n, r) -> None:
    """Put one block (``blocks.run_block_job``'s, or ``read_block(..., packed=True)``'s)
    into the space's arrays; ``correct`` holds the outcomes bit-packed."""
    acc[ti, :, s0 : s0 + n, r] = got["acc"]
    acc_subset[ti, :, s0 : s0 + n, r] = got["acc_subset"]
    k = got["bits"].shape[-1]
    correct[ti, :, s0 : s0 + n, r, :k] = got["bits"]
    finite = np.isfinite(got["loo"])
    loo[ti, finite, r] = got["loo"][finite]
