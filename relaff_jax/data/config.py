"""Dataset settings and on-disk names: ``DatasetConfig``, the folder layout, argument checks.

Takes user arguments; gives ``DatasetConfig`` (one config node with every dataset setting),
the file and folder names of a dataset directory (``SIDECAR``, ``SELECTION``, ``CHUNKS``,
``FEATURES``, ``FEATURES_SIDECAR``, ``LOCK``), the required/reserved rollout field names, and
``check_int``, ``check_action``, ``check_dataset_config``, ``jsonable_config`` which raise
``DatasetError`` with a message saying what to fix.
"""
from __future__ import annotations

import dataclasses
import json
from typing import Any, Mapping

import numpy as np

from relaff_jax import io as rio
from relaff_jax.constants import SIM_ENGINES
from relaff_jax.data.errors import DatasetError
from relaff_jax.data.selection import NEGATIVES, POPULATIONS

REQUIRED_FIELDS = ("label", "relation", "cog_distance", "toy", "other")
RESERVED_FIELDS = ("rollout", "selected", "action")

FORMAT = "relaff_jax.dataset"
FORMAT_VERSION = 1
SIDECAR = "relaff_dataset.json"
SELECTION = "selection.json"
CHUNKS = "chunks"
FEATURES = "features"
FEATURES_SIDECAR = "features.json"
LOCK = ".relaff.lock"


@dataclasses.dataclass(frozen=True)
class DatasetConfig:
    """Every dataset setting: how many samples, batch sizes, the rollout cap, negative matching.

    n_samples: balanced samples per action (N/2 positives, N/2 distance-matched negatives).
    rollout_batch: rollouts simulated per chunk (one ``rollout_fn`` call, one compile).
    feature_batch: samples per feature chunk (one perception call).
        ``generate_dataset`` and ``add_features`` take these three as explicit arguments; the
        fields let one config node (``runconfig``) hold them for the callers.
    max_rollouts: cap on simulated rollouts (rounded up to whole chunks); the paper's
        1.5M simulations over nine actions are ~170k per action. Not part of the resume
        check, so a run stopped by the cap can be rerun with a larger one.
    distance_bins: equal-width COG-distance bins spanning the selected positives' range.
    engine: executor of the motor programs, ``constants.SIM_ENGINES`` ("mjx" or "native");
        recorded in the sidecar, and resuming a dataset with another engine is refused.
    borrow_fraction: generation stops once at most this fraction of the negatives has to be
        borrowed from outside its distance bin (0 = exact histogram match). At the cap, or
        after ``match_patience``, any amount is accepted, with a warning, and the number and
        ``matching_met`` are recorded.
    population: which rollouts may be selected, ``selection.POPULATIONS``: ``"all"`` (the
        paper's reading: an infeasible program is a negative) or ``"feasible"`` (only
        rollouts whose motor program was executable; the rollouts need a ``feasible`` field).
    negatives: ``selection.NEGATIVES``: ``"cog"`` (matched on the centres' distance, the
        paper's) or ``"uniform"``.
    match_patience: once a balanced selection first exists at k chunks, simulate at most
        ``ceil(match_patience * k)`` chunks for the distance matching to be met, then accept
        the borrowing (recorded, warned). With the population "feasible" the matched
        negatives are feasible stacked pairs that fail, which may be rare: without this the
        generator would run to the cap.
    """

    max_rollouts: int = 200_000
    distance_bins: int = 20
    borrow_fraction: float = 0.01
    n_samples: int = 10_000
    rollout_batch: int = 256
    feature_batch: int = 32
    engine: str = "mjx"
    population: str = "all"
    negatives: str = "cog"
    match_patience: float = 4.0

    def __post_init__(self):  # refused when the config is made
        check_dataset_config(self)


def check_action(action: Any) -> str:
    from relaff_jax.sim.actions.registry import names

    if action not in names():  # the nine, then the user's registered actions
        raise DatasetError(f"unknown action {action!r}; valid actions: {', '.join(names())}")
    return action


def check_int(name: str, value: Any, lo: int, hi: int | None = None) -> int:
    """``value`` as an int in [lo, hi]; a ``DatasetError`` naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise DatasetError(f"{name} must be an integer, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise DatasetError(f"{name} must be {rng}, got {value}")
    return int(value)


def check_dataset_config(cfg: DatasetConfig) -> None:
    """Each setting on its own (run when a ``DatasetConfig`` is made); ``DatasetError`` naming it."""
    check_int("dataset.max_rollouts", cfg.max_rollouts, 1)
    check_int("dataset.distance_bins", cfg.distance_bins, 1)
    if isinstance(cfg.borrow_fraction, bool) or not isinstance(cfg.borrow_fraction, (int, float)) \
            or not 0.0 <= cfg.borrow_fraction <= 1.0:
        raise DatasetError(f"dataset.borrow_fraction must be in [0, 1], got {cfg.borrow_fraction!r}")
    check_int("dataset.n_samples", cfg.n_samples, 2)
    check_int("dataset.rollout_batch", cfg.rollout_batch, 1)
    check_int("dataset.feature_batch", cfg.feature_batch, 1)
    check_engine(cfg.engine)
    check_choice("population", cfg.population, POPULATIONS)
    check_choice("negatives", cfg.negatives, NEGATIVES)
    if isinstance(cfg.match_patience, bool) or not isinstance(cfg.match_patience, (int, float)) \
            or not cfg.match_patience >= 1.0:
        raise DatasetError(f"dataset.match_patience must be a number >= 1, got {cfg.match_patience!r}")


def check_choice(name: str, value: Any, valid: tuple[str, ...]) -> str:
    if value not in valid:
        raise DatasetError(f"dataset.{name} must be one of {', '.join(valid)}, got {value!r}")
    return value


def selection_scheme(cfg: DatasetConfig) -> dict[str, Any]:
    """The settings the selection depends on, as recorded in the sidecar and compared on resume."""
    return {"distance_bins": cfg.distance_bins, "borrow_fraction": cfg.borrow_fraction,
            "population": cfg.population, "negatives": cfg.negatives, "match_patience": cfg.match_patience}


def stored_scheme(scheme: Mapping[str, Any]) -> dict[str, Any]:
    """A sidecar's ``selection_scheme`` with the defaults of settings added after it was written
    (a dataset made before ``population`` existed was selected from all rollouts)."""
    return {"population": "all", "negatives": "cog", "match_patience": DatasetConfig.match_patience, **scheme}


def check_engine(engine: Any) -> str:
    if engine not in SIM_ENGINES:
        raise DatasetError(f"unknown simulation engine {engine!r}; valid engines: {', '.join(SIM_ENGINES)}")
    return engine


def jsonable_config(config_dict: Mapping[str, Any] | None) -> Any:
    """``config_dict`` as it reads back from JSON (tuples become lists), for resume checks."""
    try:
        return json.loads(json.dumps(dict(config_dict or {}), sort_keys=True, default=rio.json_default))
    except (TypeError, ValueError) as e:
        raise DatasetError(f"config_dict is not JSON serialisable ({e})") from e
