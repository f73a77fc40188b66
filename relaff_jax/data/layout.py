"""A dataset folder's layout and the checks of the arguments its functions take.

Gives the file and folder names of a dataset directory (``SIDECAR``, ``SELECTION``, ``CHUNKS``,
``FEATURES``, ``FEATURES_SIDECAR``, ``LOCK``), the required/reserved rollout field names, and
``check_int``, ``check_action``, ``jsonable_config`` which raise ``DatasetError`` with a message
saying what to fix. The dataset's settings are ``config.dataset.DatasetConfig``.
"""
from __future__ import annotations

import json
from typing import Any, Mapping

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.data.errors import DatasetError
from relaff_jax.sim.actions.registry import names

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


def check_action(action: Any) -> str:
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


def selection_scheme(cfg: DatasetConfig) -> dict[str, Any]:
    """The settings the selection depends on, as recorded in the sidecar and compared on resume."""
    return {"distance_bins": cfg.distance_bins, "borrow_fraction": cfg.borrow_fraction,
            "population": cfg.population, "negatives": cfg.negatives, "match_patience": cfg.match_patience,
            "unsettled": cfg.unsettled}


def stored_scheme(scheme: Mapping[str, Any]) -> dict[str, Any]:
    """A sidecar's ``selection_scheme`` with the defaults of settings added after it was written
    (a dataset made before ``population`` existed was selected from all rollouts, one made
    before ``unsettled`` kept the rollouts still moving at the hold's end)."""
    return {"population": "all", "negatives": "cog", "match_patience": DatasetConfig.match_patience,
            "unsettled": "keep", **scheme}


def scheme_changes(stored: Mapping[str, Any], wanted: Mapping[str, Any]) -> list[str]:
    """``"key old -> new"`` for each selection setting a sidecar's scheme (``stored_scheme``
    applied to it) and the wanted one (``selection_scheme``) differ in; [] when none. The
    generator selects again where this is not empty, and the reproduce status says so."""
    old = stored_scheme(stored)
    return [f"{k} {old.get(k)!r} -> {wanted[k]!r}" for k in sorted(wanted) if old.get(k) != wanted[k]]


def jsonable_config(config_dict: Mapping[str, Any] | None) -> Any:
    """``config_dict`` as it reads back from JSON (tuples become lists), for resume checks."""
    try:
        return json.loads(json.dumps(dict(config_dict or {}), sort_keys=True, default=rio.json_default))
    except (TypeError, ValueError) as e:
        raise DatasetError(f"config_dict is not JSON serialisable ({e})") from e
