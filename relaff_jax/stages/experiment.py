"""Stage 3, ``experiment``: the learning and bootstrapping sweeps in every state space
(``relaff_jax.learn.sweep.run_experiment``), in ``DIR/results/``.

``experiment_folder(tree, data, out, seed=...)`` runs (or resumes) the experiment of one
results folder and writes its config record: what ``relaff experiment`` calls, and what
``run(run, forced)`` calls with the run folder's datasets and the experiment seed from the run
log. The protocol comes from ``tree.experiment`` and the spaces from ``tree.reproduce.spaces``
only. ``learn`` keeps the computation.
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

from relaff_jax import io as rio
from relaff_jax.sim.actions.registry import names  # the run's actions (no JAX)
from relaff_jax.errors import UserError
from relaff_jax.stages.protocol import Run, ReproduceError, Status
from relaff_jax.io import check_writable_dir
from relaff_jax.provenance import record_config
from relaff_jax.config import override
from relaff_jax.learn.checks import check_config
from relaff_jax.data import load_dataset
from relaff_jax.learn.status import experiment_status, sweep_progress
from relaff_jax.data.status import manifest_fingerprint
from relaff_jax.learn.synthetic import synthetic_datasets

NAME = "experiment"
COMMAND = "experiment"  # the command the folder's config record names


def experiment_folder(tree: Any, data: Sequence[str | os.PathLike] | Mapping[str, Mapping[str, Any]] | int,
                      out: str | os.PathLike, *, seed: int = 0, jobs: int = 0, client: Any = None,
                      progress: bool = True, data_desc: Sequence[str] | None = None,
                      reuse: str | os.PathLike | None = None) -> dict[str, Path]:
    """Run (or resume) the experiment of ``tree`` on ``data`` in ``out``; record the tree there.
    Returns ``{space: OUT/SPACE/results.npz}``.

    tree: a ``RunConfig``; ``tree.experiment`` is the protocol, ``tree.reproduce.spaces`` the
      spaces swept. The record (``provenance.record_config``, command ``"experiment"``) holds
      the tree with ``reproduce.actions`` set to the actions that ran (those of ``data``), so
      that it says what this folder holds.
    data: dataset folders, one per action (``learn.load_datasets``); or ``{action: dataset}``
      already loaded (``data_desc``: what ``experiment.json`` names them by, default none);
      or an int N: N synthetic samples per action of ``tree.reproduce.actions``
      (``learn.synthetic_datasets(N, seed)``, a dry run of the stage).
    seed: the seed of the test draws, training orders and forests. jobs: worker processes
      (0: every core). client: a ``distributed.Client``: sweep blocks run as its tasks, with
      the same bits. progress: a progress bar on stderr. reuse: another reading's results
      folder whose unchanged conditions are read, not refitted (``learn.reuse``).
    Mistakes a user can fix (a missing folder, an output that cannot be written) are
    ``UserError``s raised before any dataset is read or any forest fitted.
    """
    if isinstance(data, (str, os.PathLike)):
        data = [data]  # one folder, not its name's characters
    folders = None if isinstance(data, (int, Mapping)) else list(data)
    for d in folders or ():  # before anything is read (the experiment's own imports take seconds)
        if not Path(d).is_dir():
            raise UserError(f"{d}: no such dataset directory")
    check_writable_dir(Path(out), "--out")
    if reuse is not None and not Path(reuse).is_dir():
        raise UserError(f"--reuse {reuse}: no such folder")
    # by name here: this module's own load_datasets would shadow it at the top
    from relaff_jax.learn.datasets import load_datasets
    # loaded when the stage runs: reproduce --status and the command's checks read this module
    from relaff_jax.learn.sweep import run_experiment

    check_config(tree.experiment)  # the learner and the user's conditions tried once, before the data are read
    if isinstance(data, Mapping):
        datasets, desc = dict(data), list(data_desc or ())
    elif isinstance(data, int):
        datasets, desc = synthetic_datasets(data, seed=seed, actions=tree.reproduce.actions), [f"synthetic:{data}"]
    else:
        datasets, desc = load_datasets(folders), [str(d) for d in folders]
    jobs = jobs if jobs and jobs > 0 else (os.cpu_count() or 1)
    paths = run_experiment(datasets, out, tree.experiment, list(tree.reproduce.spaces), seed=seed, jobs=jobs,
                           progress=progress, data_desc=desc, client=client, reuse=reuse)
    ran = tuple(a for a in names() if a in datasets)  # run_experiment checked they are the run's actions
    record_config(out, override(tree, {"reproduce.actions": ran}), COMMAND)
    return paths


def load_datasets(run: Run) -> dict[str, dict]:
    """``{action: dataset}`` of the run folder, each with its features."""
    out = {}
    for a in run.cfg.reproduce.actions:
        d = load_dataset(run.paths.dataset(a))
        if "pca" not in d or "rhf" not in d:
            raise ReproduceError(f"{run.paths.dataset(a)} has no features; run the features stage")
        out[a] = d
    return out


def status(run: Run, datasets: dict | None = None) -> Status:
    res = run.paths.results
    if not res.exists():
        return Status("absent", "no results folder")
    c = run.cfg
    prints = None if datasets is not None or run.verify else recorded_fingerprints(run)
    if datasets is None and prints is None:
        datasets = load_datasets(run)
    return Status(*experiment_status(res, datasets, c.experiment, run.log["seeds"]["experiment"],
                                     c.reproduce.actions, c.reproduce.spaces, fingerprints=prints))


def recorded_fingerprints(run: Run) -> dict[str, dict[str, str]] | None:
    """``{space: {action: sha256}}`` of the run's datasets from their status manifests
    (``data.status.manifest_fingerprint``, recorded when their features finished), without
    loading them; None if any dataset's cannot be vouched for (then the datasets are loaded)."""
    spaces, out = run.cfg.reproduce.spaces, {}
    for a in run.cfg.reproduce.actions:
        fp = manifest_fingerprint(run.paths.dataset(a))
        if fp is None or any(s not in fp for s in spaces):
            return None
        out[a] = fp
    return {s: {a: out[a][s] for a in sorted(out)} for s in spaces}


def progress(run: Run) -> float:
    c = run.cfg
    return sweep_progress(run.paths.results, c.experiment, len(c.reproduce.actions), c.reproduce.spaces)


def run(run: Run, forced: bool) -> dict:
    cfg, res = run.cfg, run.paths.results
    run.progress.set("loading datasets")
    datasets = load_datasets(run)
    st = Status("absent", "forced") if forced else status(run, datasets)
    if forced or st.state in ("stale", "corrupt"):
        if st.state != "absent":
            run.progress.message(f"experiment: {res}: {st.why}; recomputing")
        rio.remove_tree(res)
    spaces = cfg.reproduce.spaces
    run.progress.set(f"{' + '.join(s.upper() for s in spaces)} sweeps")
    t0 = time.perf_counter()
    experiment_folder(cfg, datasets, res, seed=run.log["seeds"]["experiment"], jobs=run.jobs, client=run.client,
                      progress=False, data_desc=[str(run.paths.dataset(x)) for x in cfg.reproduce.actions])
    dt = time.perf_counter() - t0
    run.progress.message(f"experiment: {', '.join(spaces)} sweeps in {dt:.0f} s")
    return {"status": "ran", "was": "forced" if forced else st.state, "seconds": round(dt, 2)}
