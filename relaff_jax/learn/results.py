"""Reading an experiment folder written by ``sweep.run_experiment``.

``load_results(RESULTS)`` gives ``{"meta": experiment.json, "config": ExperimentConfig,
<space>: {acc, sizes, actions, conditions, thresholds, corr, category_masks, test_size, ...}}``;
``is_complete`` says whether every requested space has finished.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import from_dict
from relaff_jax.constants import SPACES
from relaff_jax.errors import UserError
from relaff_jax.learn.config import ExperimentConfig

FORMAT_VERSION = 1  # of experiment.json and results.npz


class ResultsNotFound(UserError, FileNotFoundError):
    """A folder that is not a (finished) experiment folder."""


def is_complete(out: str | os.PathLike, spaces: Sequence[str] = SPACES) -> bool:
    """Whether ``out`` holds finished results for every one of ``spaces``."""
    out = Path(out)
    if not (out / "experiment.json").exists():
        return False
    try:
        done = rio.read_json(out / "experiment.json")["spaces"]
    except (ValueError, KeyError):
        return False
    return all(s in done and (out / s / "results.npz").exists() for s in spaces)


def load_results(results_dir: str | os.PathLike) -> dict[str, Any]:
    """``{"meta": experiment.json, "config": ExperimentConfig, <space>: {arrays}}``."""
    root = Path(results_dir)
    meta_path = root / "experiment.json"
    if not meta_path.exists():
        raise ResultsNotFound(f"{root} is not an experiment folder (no experiment.json)")
    meta = rio.read_json(meta_path)
    out: dict[str, Any] = {"meta": meta, "config": from_dict(ExperimentConfig, meta["config"])}
    for space in meta["spaces"]:
        p = root / space / "results.npz"
        if not p.exists():
            raise ResultsNotFound(f"{p} missing: the {space} sweep has not finished (rerun `relaff experiment`)")
        with np.load(p) as z:
            out[space] = {k: z[k] for k in z.files}
    return out
