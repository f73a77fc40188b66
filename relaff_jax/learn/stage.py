"""The experiment stage's one entry point: ``run(tree, data, out, ...)``, what ``relaff
experiment`` and ``relaff reproduce`` both call.

Takes the whole config tree (``runconfig.RunConfig``: its ``experiment`` node is the protocol,
``reproduce.spaces`` the state spaces swept), the input datasets (folders, loaded datasets or a
synthetic sample count), the results folder and the run's seed, jobs and cluster client;
checks the inputs before any work, runs (or resumes) ``sweep.run_experiment`` and writes the
folder's config record (``provenance.record_config``, command ``"experiment"``) in one shape for
both routes. Returns ``{space: OUT/SPACE/results.npz}``.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from relaff_jax.sim.actions.registry import names  # the run's actions (no JAX)
from relaff_jax.errors import UserError

COMMAND = "experiment"


def run(tree: Any, data: Sequence[str | os.PathLike] | Mapping[str, Mapping[str, Any]] | int,
        out: str | os.PathLike, *, seed: int = 0, jobs: int = 0, client: Any = None, progress: bool = True,
        data_desc: Sequence[str] | None = None) -> dict[str, Path]:
    """Run (or resume) the experiment of ``tree`` on ``data`` in ``out``; record the tree there.

    tree: a ``RunConfig``; ``tree.experiment`` is the protocol, ``tree.reproduce.spaces`` the
      spaces swept. The record holds the tree with ``reproduce.actions`` set to the actions
      that ran (those of ``data``), so that it says what this folder holds.
    data: dataset folders, one per action (``load_datasets``); or ``{action: dataset}``
      already loaded (``data_desc``: what ``experiment.json`` names them by, default none);
      or an int N: N synthetic samples per action of ``tree.reproduce.actions``
      (``synthetic_datasets(N, seed)``, a dry run of the stage).
    seed: the seed of the test draws, training orders and forests. jobs: worker processes
      (0: every core). client: a ``distributed.Client``: sweep blocks run as its tasks, with
      the same bits. progress: a progress bar on stderr.
    Mistakes a user can fix (a missing folder, an output that cannot be written) are
    ``UserError``s raised before any dataset is read or any forest fitted.
    """
    from relaff_jax.io import check_writable_dir
    from relaff_jax.provenance import record_config

    if isinstance(data, (str, os.PathLike)):
        data = [data]  # one folder, not its name's characters
    folders = None if isinstance(data, (int, Mapping)) else list(data)
    for d in folders or ():  # before anything is read (the experiment's own imports take seconds)
        if not Path(d).is_dir():
            raise UserError(f"{d}: no such dataset directory")
    check_writable_dir(Path(out), "--out")
    from relaff_jax.config import override
    from relaff_jax.learn.config import check_config
    from relaff_jax.learn.datasets import load_datasets
    from relaff_jax.learn.sweep import run_experiment
    from relaff_jax.learn.synthetic import synthetic_datasets

    check_config(tree.experiment)  # the learner and the user's conditions tried once, before the data are read
    if isinstance(data, Mapping):
        datasets, desc = dict(data), list(data_desc or ())
    elif isinstance(data, int):
        datasets, desc = synthetic_datasets(data, seed=seed, actions=tree.reproduce.actions), [f"synthetic:{data}"]
    else:
        datasets, desc = load_datasets(folders), [str(d) for d in folders]
    jobs = jobs if jobs and jobs > 0 else (os.cpu_count() or 1)
    paths = run_experiment(datasets, out, tree.experiment, list(tree.reproduce.spaces), seed=seed, jobs=jobs,
                           progress=progress, data_desc=desc, client=client)
    ran = tuple(a for a in names() if a in datasets)  # run_experiment checked they are the run's actions
    record_config(out, override(tree, {"reproduce.actions": ran}), COMMAND)
    return paths
