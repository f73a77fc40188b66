"""Reading an experiment folder written by ``sweep.run_experiment``.

``load_results(RESULTS)`` gives a typed ``Results``: ``meta`` (experiment.json), ``config``
(``ExperimentConfig``) and per finished space a ``SpaceResults`` of arrays; both also read as
mappings (``res["pca"]["acc"]``), as the report and notebooks use them. ``is_complete`` says
whether every requested space has finished.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Iterator, Mapping

import chex
import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import from_dict
from relaff_jax.constants import SPACES
from relaff_jax.errors import UserError
from relaff_jax.learn import folder as L
from relaff_jax.config.experiment import ExperimentConfig

FORMAT_VERSION = 2  # of experiment.json and results.npz (2: balanced test sets, outcomes, leave-one-out)


class ResultsNotFound(UserError, FileNotFoundError):
    """A folder that is not a (finished) experiment folder."""


@chex.dataclass(frozen=True)
class SpaceResults:
    """One state space's sweep (``results.npz``); T targets, C conditions, S sizes, R reps.

    acc (T, C, S, R) test accuracy (NaN where a condition does not apply); sizes (S,);
    actions (T,) names; conditions (C,) names; thresholds (K,) of the correlation heuristic;
    corr (T, T) predictor correlation; category_masks (K, T, P) categories kept per threshold;
    test_size (T,) test scenes per target, test_positive (T,) how many of them are positive;
    loo (T, C, R) leave-one-out accuracy at ``select_size`` of the DB1 and CB1 candidates;
    acc_subset (T, C, S, R, 3) test accuracy on each test subset (``blocks.SUBSETS``:
    positives, feasible negatives, infeasible negatives; NaN where a subset is empty or
    unknown); subset_count (T, 3) test scenes per subset; corr_feasible, corr_stacked (T,)
    each source predictor's correlation on the correlation scenes with "feasible" and with
    "stacked" (on_top or inside), NaN where undefined;
    correct (T, C, S, R, N) bool outcome per test scene, read as ``PackedBits`` (unpacked where
    indexed; N = the largest ``n_test``; scenes past a target's ``n_test`` are padding; N = 0
    when the run kept no outcomes);
    seconds, seconds_prep, new_fits: scalars of the run.
    """

    acc: np.ndarray
    sizes: np.ndarray
    actions: np.ndarray
    conditions: np.ndarray
    thresholds: np.ndarray
    corr: np.ndarray
    category_masks: np.ndarray
    test_size: np.ndarray
    test_positive: np.ndarray
    loo: np.ndarray
    acc_subset: np.ndarray
    subset_count: np.ndarray
    corr_feasible: np.ndarray
    corr_stacked: np.ndarray
    correct: np.ndarray
    n_test: np.ndarray
    seconds: np.ndarray
    seconds_prep: np.ndarray
    new_fits: np.ndarray


@dataclasses.dataclass(frozen=True)
class Results(Mapping[str, Any]):
    """An experiment folder's results: ``meta``, ``config`` and one ``SpaceResults`` per
    finished space (``spaces``); ``res[name]`` reads any of them."""

    meta: dict
    config: ExperimentConfig
    spaces: dict[str, SpaceResults]

    def __getitem__(self, key: str) -> Any:
        if key in ("meta", "config"):
            return getattr(self, key)
        return self.spaces[key]

    def __iter__(self) -> Iterator[str]:
        return iter(("meta", "config", *self.spaces))

    def __len__(self) -> int:
        return 2 + len(self.spaces)


is_complete = L.is_complete  # in folder.py, so that a status imports no JAX


class PackedBits:
    """Bit-packed outcomes ``packed (..., ceil(N / 8))`` read as a bool array ``(..., N)``,
    unpacked only where indexed (the paper preset's PCA outcomes are 8.9 GB as bools, 1.1 GB
    packed). Index the leading axes only; ``np.asarray`` unpacks the whole."""

    dtype = np.dtype(bool)

    def __init__(self, packed: np.ndarray, n: int):
        self.packed, self.n = packed, int(n)
        self.shape = tuple(packed.shape[:-1]) + (self.n,)
        self.ndim = len(self.shape)

    def __getitem__(self, key) -> np.ndarray:
        # unpackbits gives 0/1 bytes: read as bool in place (astype copied every unpacked byte)
        return np.unpackbits(self.packed[key], axis=-1, count=self.n).view(bool)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        full = self[...]
        return full if dtype is None else full.astype(dtype)


def _check_meta(meta_path: Path, meta: Any) -> None:
    """``experiment.json`` is this program's: a JSON object with its format, spaces, actions
    and config; a foreign or hand-edited file is refused by name."""
    def bad(what):
        return ResultsNotFound(f"{meta_path}: not an experiment record of relaff_jax ({what}); give the folder "
                               "`relaff experiment --out` wrote, or rerun the experiment")

    if not isinstance(meta, dict):
        raise bad(f"a JSON {type(meta).__name__}, not an object")
    missing = [k for k in ("format", "spaces", "actions", "config") if k not in meta]
    if missing:
        raise bad(f"no {', '.join(missing)}")
    if meta["format"] != FORMAT_VERSION:
        raise bad(f"format {meta['format']!r}, this version reads {FORMAT_VERSION}")
    if not isinstance(meta["spaces"], list) or not set(map(str, meta["spaces"])) <= set(SPACES) or not meta["spaces"]:
        raise bad(f"spaces {meta['spaces']!r:.60}, expected some of {list(SPACES)}")
    if not isinstance(meta["actions"], list) or not all(isinstance(a, str) for a in meta["actions"]):
        raise bad(f"actions {meta['actions']!r:.60}")
    if not isinstance(meta["config"], dict):
        raise bad("config is not an object")


def load_results(results_dir: str | os.PathLike) -> Results:
    """The ``Results`` of an experiment folder (every space in its ``experiment.json``).
    A foreign or damaged ``experiment.json`` or ``results.npz`` is a ``UserError`` naming the file."""
    root = Path(results_dir)
    meta_path = L.meta(root)
    if not meta_path.exists():
        raise ResultsNotFound(f"{root} is not an experiment folder (no {L.META})")
    meta = rio.read_json(meta_path)
    _check_meta(meta_path, meta)
    try:
        config = from_dict(ExperimentConfig, meta["config"])
    except (TypeError, ValueError, AttributeError) as e:
        raise ResultsNotFound(f"{meta_path}: its config cannot be read by this version ({e})") from e
    spaces: dict[str, SpaceResults] = {}
    for space in meta["spaces"]:
        p = L.results(root, space)
        if not p.exists():
            raise ResultsNotFound(f"{p} missing: the {space} sweep has not finished (rerun `relaff experiment`)")
        arrays = rio.load_npz(p)
        missing = {f.name for f in dataclasses.fields(SpaceResults)} - set(arrays)
        if missing:
            raise ResultsNotFound(f"{p} lacks {sorted(missing)}: written by another version; rerun the experiment")
        n = int(arrays["n_test"].max(initial=0))
        arrays["correct"] = PackedBits(arrays["correct"], n)
        spaces[space] = SpaceResults(**{f.name: arrays[f.name] for f in dataclasses.fields(SpaceResults)})
    return Results(meta=meta, config=config, spaces=spaces)
