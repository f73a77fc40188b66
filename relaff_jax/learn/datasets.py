"""The learning stage's input: one featured dataset per action, checked and fingerprinted.

Takes dataset folders (``load_datasets``) or ``{action: dataset}`` dicts (``load_dataset``'s
layout, or ``synthetic_datasets``); ``check_datasets`` validates them and gives the present
actions in canonical order; ``fingerprint`` gives ``{space: {action: sha256}}`` of what a
space's sweep reads, so that a resumed sweep provably sees the same data.
"""
from __future__ import annotations

import hashlib
import os
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.sim.actions.registry import names  # the run's actions (no JAX)
from relaff_jax.errors import UserError
from relaff_jax.data import load_dataset


def check_datasets(datasets: Mapping[str, Mapping[str, Any]], spaces: Sequence[str]) -> list[str]:
    """Validate ``{action: dataset}``; return the present actions in canonical order."""
    if len(datasets) < 2:
        raise UserError(f"bootstrapping needs datasets of at least two actions, got {sorted(datasets)}")
    for action, d in datasets.items():
        if action not in names():  # the nine, then the user's registered actions
            raise UserError(f"unknown action {action!r}; expected one of {names()}")
        if "action" in d and str(d["action"]) != action:
            raise UserError(f"dataset given for {action!r} says its action is {d['action']!r}")
        for key in ("label", "pca") + (("rhf",) if "rhf" in spaces else ()):
            if key not in d:
                raise UserError(f"{action} dataset has no {key!r} array (needed for spaces {list(spaces)})")
        n = len(d["label"])
        if np.shape(d["pca"]) != (n, 18):
            raise UserError(f"{action}: pca must be (N, 18) with N = {n} labels, got {np.shape(d['pca'])}")
        if "rhf" in spaces and np.shape(d["rhf"]) != (n, 300):
            raise UserError(f"{action}: rhf must be (N, 300) with N = {n} labels, got {np.shape(d['rhf'])}")
        for key in ("pca",) + (("rhf",) if "rhf" in spaces else ()):
            if not np.all(np.isfinite(d[key])):
                raise UserError(f"{action}: {key} features contain NaN or inf")
    return [a for a in names() if a in datasets]


def fingerprint(datasets: Mapping[str, Mapping[str, Any]], spaces: Sequence[str]) -> dict[str, dict[str, str]]:
    """``{space: {action: sha256}}`` of the labels and the space's features: a resumed sweep
    must see the same data."""
    out: dict[str, dict[str, str]] = {}
    for space in spaces:
        out[space] = {}
        for action in sorted(datasets):
            h = hashlib.sha256()
            for key in ("label", "pca") + (("rhf",) if space == "rhf" else ()):
                h.update(np.ascontiguousarray(np.asarray(datasets[action][key], dtype=np.float32)).tobytes())
            out[space][action] = h.hexdigest()
    return out


def load_datasets(dirs: Sequence[str | os.PathLike]) -> dict[str, dict]:
    """``{action: load_dataset(DIR)}`` for the given dataset directories."""
    out: dict[str, dict] = {}
    for d in dirs:
        data = load_dataset(d)
        action = str(data["action"])
        if action in out:
            raise UserError(f"two datasets for action {action!r} (second: {d})")
        out[action] = data
    return out
