"""Stage 3, ``experiment``: the learning and bootstrapping sweeps in every state space
(``relaff_jax.learn.run``, what ``relaff experiment`` runs), in ``DIR/results/``."""
from __future__ import annotations

import time

from relaff_jax import io as rio
from relaff_jax.reproduce.folder import ReproduceError
from relaff_jax.reproduce.stage import Run, Status

NAME = "experiment"


def load_datasets(run: Run) -> dict[str, dict]:
    from relaff_jax.data import load_dataset

    out = {}
    for a in run.cfg.reproduce.actions:
        d = load_dataset(run.paths.dataset(a))
        if "pca" not in d or "rhf" not in d:
            raise ReproduceError(f"{run.paths.dataset(a)} has no features; run the features stage")
        out[a] = d
    return out


def status(run: Run, datasets: dict | None = None) -> Status:
    from relaff_jax.learn.status import experiment_status

    res = run.paths.results
    if not res.exists():
        return Status("absent", "no results folder")
    datasets = load_datasets(run) if datasets is None else datasets
    c = run.cfg
    return Status(*experiment_status(res, datasets, c.experiment, run.log["seeds"]["experiment"],
                                     c.reproduce.actions, c.reproduce.spaces))


def progress(run: Run) -> float:
    from relaff_jax.learn.status import sweep_progress

    c = run.cfg
    return sweep_progress(run.paths.results, c.experiment, len(c.reproduce.actions), c.reproduce.spaces)


def run(run: Run, forced: bool) -> dict:
    from relaff_jax import learn

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
    learn.run(cfg, datasets, res, seed=run.log["seeds"]["experiment"], jobs=run.jobs, client=run.client,
              progress=False, data_desc=[str(run.paths.dataset(x)) for x in cfg.reproduce.actions])
    dt = time.perf_counter() - t0
    run.progress.message(f"experiment: {', '.join(spaces)} sweeps in {dt:.0f} s")
    return {"status": "ran", "was": "forced" if forced else st.state, "seconds": round(dt, 2)}
