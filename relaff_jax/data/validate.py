"""Checks that bring rollout and feature outputs to storage types, and per-field schemas.

Takes what a ``rollout_fn`` or a feature ``compute_fn`` returned for one batch; gives a dict
of numpy arrays (strings as numpy ``str``, labels bool, int relation codes and object ids
turned into names) or a ``DatasetError`` saying which field is wrong. ``schema_of`` gives
each field's dtype and per-sample shape; ``check_schema`` refuses a chunk whose fields differ
from earlier chunks'. ``check_dataset_dir`` tells, before any simulation, whether a folder can
take (or resume) a dataset of given settings.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.constants import RELATIONS
from relaff_jax.data.layout import CHUNKS, LOCK, REQUIRED_FIELDS, RESERVED_FIELDS, SELECTION, SIDECAR
from relaff_jax.data.errors import CorruptDatasetError, DatasetError, DatasetMismatchError, ForeignDirectoryError
from relaff_jax.data.store import mismatch, read_sidecar

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _as_strings(name: str, a: np.ndarray) -> np.ndarray:
    if a.dtype.kind == "S":
        return np.char.decode(a, "utf-8").astype(str)
    if a.dtype.kind == "O":
        if not all(isinstance(v, str) for v in a.ravel()):
            raise DatasetError(f"{name}: object array must hold only str values")
        return a.astype(str)
    return a


def standardize_rollouts(out: Any, batch: int, object_names: Sequence[str] | None) -> dict[str, np.ndarray]:
    """Check a rollout_fn result and bring it to storage types (strings as numpy str)."""
    if not isinstance(out, Mapping):
        raise DatasetError(f"rollout_fn must return a dict of arrays, got {type(out).__name__}")
    missing = [k for k in REQUIRED_FIELDS if k not in out]
    if missing:
        raise DatasetError(f"rollout_fn result lacks required field(s) {missing}")
    arrays: dict[str, np.ndarray] = {}
    for name, value in out.items():
        if not isinstance(name, str) or not NAME_RE.match(name):
            raise DatasetError(f"rollout field name {name!r} is not an identifier")
        if name in RESERVED_FIELDS:
            raise DatasetError(f"rollout field name {name!r} is reserved (added by the dataset)")
        a = _as_strings(name, np.asarray(value))
        if a.ndim == 0 or a.shape[0] != batch:
            raise DatasetError(
                f"rollout field {name!r} has shape {a.shape}; expected leading axis {batch}"
            )
        if a.dtype.kind not in "biufcU":
            raise DatasetError(f"rollout field {name!r} has unsupported dtype {a.dtype}")
        arrays[name] = a
    lab = arrays["label"]
    if lab.dtype.kind != "b":
        if lab.dtype.kind not in "iu" or not np.isin(lab, (0, 1)).all():
            raise DatasetError(f"label must be bool (or 0/1 ints), got dtype {lab.dtype}")
        arrays["label"] = lab.astype(bool)
    for name in ("label", "relation", "cog_distance", "toy", "other"):
        if arrays[name].ndim != 1:
            raise DatasetError(f"{name} must have shape ({batch},), got {arrays[name].shape}")
    rel = arrays["relation"]
    if rel.dtype.kind in "iu":
        if rel.size and (rel.min() < 0 or rel.max() >= len(RELATIONS)):
            raise DatasetError(f"relation int codes must index {RELATIONS}")
        rel = np.asarray(RELATIONS)[rel]
    if rel.dtype.kind != "U" or not np.isin(rel, RELATIONS).all():
        bad = sorted(set(rel.tolist()) - set(RELATIONS)) if rel.dtype.kind == "U" else rel.dtype
        raise DatasetError(f"relation must be one of {RELATIONS}; got {bad}")
    arrays["relation"] = rel
    d = arrays["cog_distance"]
    if d.dtype.kind not in "iuf" or not np.all(np.isfinite(d)) or np.any(d < 0):
        raise DatasetError("cog_distance must be finite, non-negative numbers")
    if d.dtype.kind != "f":
        arrays["cog_distance"] = d.astype(np.float64)
    for name in ("toy", "other"):
        a = arrays[name]
        if a.dtype.kind in "iu":
            if object_names is None:
                raise DatasetError(f"{name} holds int ids but no object_names table was given")
            if a.min() < 0 or a.max() >= len(object_names):
                raise DatasetError(f"{name} ids out of range for object_names")
            arrays[name] = np.asarray(object_names)[a]
        elif a.dtype.kind != "U":
            raise DatasetError(f"{name} must be object names (str) or int ids, got {a.dtype}")
    return arrays


def schema_of(arrays: Mapping[str, np.ndarray]) -> dict[str, list]:
    return {k: ["str" if a.dtype.kind == "U" else a.dtype.str, list(a.shape[1:])] for k, a in arrays.items()}


def check_schema(where: str, schema: Mapping[str, list], ref: Mapping[str, list] | None) -> None:
    if ref is None:
        return
    if set(schema) != set(ref):
        raise DatasetError(
            f"{where}: fields {sorted(schema)} differ from earlier chunks' {sorted(ref)}"
        )
    for k in ref:
        if list(schema[k]) != list(ref[k]):
            raise DatasetError(f"{where}: field {k!r} is {schema[k]}, earlier chunks {ref[k]}")


def standardize_features(out: Any, batch: int, taken: set[str]) -> dict[str, np.ndarray]:
    if not isinstance(out, Mapping) or not out:
        raise DatasetError("compute_fn must return a non-empty dict of arrays")
    arrays = {}
    for name, value in out.items():
        if not isinstance(name, str) or not NAME_RE.match(name):
            raise DatasetError(f"feature name {name!r} is not an identifier")
        if name in taken or name in RESERVED_FIELDS:
            raise DatasetError(f"feature name {name!r} collides with a stored sample field")
        a = np.asarray(value)
        if a.ndim == 0 or a.shape[0] != batch:
            raise DatasetError(f"feature {name!r} has shape {a.shape}; expected leading axis {batch}")
        if a.dtype.kind not in "biuf":
            raise DatasetError(f"feature {name!r} must be numeric or bool, got {a.dtype}")
        arrays[name] = a
    if "unseen" in arrays and arrays["unseen"].dtype.kind != "b":
        raise DatasetError(f"feature 'unseen' must be bool, got {arrays['unseen'].dtype}")
    return arrays


def check_dataset_dir(path: Path, expected: Mapping[str, Any]) -> None:
    """What ``prepare_dir`` and a resume would refuse, told before any simulation is built
    (MJX compiles for minutes): ``path`` a file, a foreign non-empty folder, a truncated
    dataset, or a dataset of other ``expected`` sidecar values (action, seed, ...). Writes nothing."""
    path = Path(path)
    if not path.exists() or (path.is_dir() and not any(p.name != LOCK for p in path.iterdir())):
        return
    if not path.is_dir():
        raise DatasetError(f"{path}: exists and is not a directory")
    if not (path / SIDECAR).exists():
        if (path / CHUNKS).exists() or (path / SELECTION).exists():
            raise CorruptDatasetError(f"{path}: dataset sidecar {SIDECAR} is missing (truncated dataset)")
        raise ForeignDirectoryError(f"{path}: exists, is not empty and is not a relaff dataset; give a new or "
                                    "empty folder")

    meta = read_sidecar(path)
    diff = mismatch(meta, dict(expected), sorted(expected))
    if diff:
        raise DatasetMismatchError(f"{path}: holds a different dataset; " + "; ".join(diff)
                                   + "; write to a new folder, or resume it with its own settings")
