"""Reading a dataset directory: every rollout, the balanced selection, attached features.

Takes a dataset directory; gives ``load_rollouts`` (R, ...) arrays of every stored rollout
with a ``selected`` mask, ``load_dataset`` (N, ...) arrays of the selected samples plus the
finished features, and the feature-store readers ``read_features_sidecar`` and
``load_feature_chunks``. Every chunk is verified (checksums, rollout ids, schema) and the
selection index against the sidecar; damage is a ``CorruptDatasetError``.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from relaff_jax import io as rio
from relaff_jax.data.layout import CHUNKS, FEATURES, FEATURES_SIDECAR, SELECTION
from relaff_jax.data.errors import CorruptDatasetError, DatasetError
from relaff_jax.data.store import (check_rollout_ids, chunk_indices, chunk_path, concat, read_chunk, read_sidecar,
                                   sha256)
from relaff_jax.data.validate import check_schema, schema_of


def load_chunks(path: Path, meta: Mapping[str, Any]) -> dict[str, np.ndarray]:
    cdir = path / CHUNKS
    done = chunk_indices(cdir)
    want = meta["counts"]["chunks"]
    if len(done) < want or (meta["status"] == "complete" and len(done) != want):
        raise CorruptDatasetError(f"{path}: sidecar records {want} chunks, found {len(done)} (truncated dataset)")
    parts, schema = [], None
    for k in done:
        arrays, _ = read_chunk(chunk_path(cdir, k))
        check_rollout_ids(chunk_path(cdir, k), arrays, k, meta["batch"])
        check_schema(f"{chunk_path(cdir, k)}", schema_of(arrays), schema)
        schema = schema or schema_of(arrays)
        parts.append(arrays)
    if not parts:  # nothing simulated yet: empty required fields keep info() working
        return {
            "label": np.zeros(0, bool), "relation": np.zeros(0, str), "cog_distance": np.zeros(0),
            "toy": np.zeros(0, str), "other": np.zeros(0, str), "rollout": np.zeros(0, np.int64),
        }
    return concat(parts)


def read_selection(path: Path, meta: Mapping[str, Any], rollouts: Mapping[str, np.ndarray]) -> np.ndarray:
    try:
        index = rio.read_json(path / SELECTION)
    except FileNotFoundError:
        raise CorruptDatasetError(f"{path}: selection index {SELECTION} is missing (truncated dataset)") from None
    except (OSError, ValueError) as e:
        raise CorruptDatasetError(f"{path}: selection index {SELECTION} is corrupt ({e})") from e
    try:
        sel = np.asarray(index["selected"], dtype=np.int64)
    except (KeyError, TypeError, ValueError) as e:
        raise CorruptDatasetError(f"{path}: selection index {SELECTION} is corrupt ({e})") from e
    n = meta["n_samples"]
    r = len(rollouts.get("label", ()))
    if (
        sel.shape != (n,)
        or sha256(sel) != meta.get("selection", {}).get("sha256")
        or (n and (sel.min() < 0 or sel.max() >= r))
        or np.any(np.diff(sel) <= 0)
    ):
        raise CorruptDatasetError(f"{path}: selection index {SELECTION} does not match the sidecar or chunks")
    if int(rollouts["label"][sel].sum()) != n // 2:
        raise CorruptDatasetError(f"{path}: selected labels are not balanced (chunks changed after selection)")
    return sel


def load_rollouts(path: str | os.PathLike) -> dict[str, Any]:
    """Every stored rollout, selected or not.

    Returns (R, ...) arrays: the rollout_fn fields (strings as numpy str), ``rollout`` (R,)
    int64 global index, ``selected`` (R,) bool (all False while still generating), and
    ``action`` (str).
    """
    path = Path(path)
    meta = read_sidecar(path)
    out: dict[str, Any] = load_chunks(path, meta)
    mask = np.zeros(len(out.get("rollout", ())), bool)
    if meta["status"] == "complete":
        mask[read_selection(path, meta, out)] = True
    out["selected"] = mask
    out["action"] = meta["action"]
    return out


def load_dataset(path: str | os.PathLike, *, features: bool = True) -> dict[str, Any]:
    """The selected, balanced samples of a finished dataset as named numpy arrays.

    Returns (N, ...) arrays in rollout order: ``label`` bool, ``relation`` str of
    ``RELATIONS``, ``cog_distance`` float, ``toy``/``other`` object names, ``rollout`` int64,
    every other stored per-sample field; the attached features (e.g. ``pca`` (N, 18),
    ``rhf`` (N, 300), ``unseen`` (N, 2) bool) once ``add_features`` has finished (and
    ``features=True``); and ``action`` (str).
    """
    path = Path(path)
    meta = read_sidecar(path)
    if meta["status"] != "complete":
        c = meta["counts"]
        raise DatasetError(
            f"{path}: generation not finished ({c['rollouts']} rollouts in {c['chunks']} chunks so far); "
            "rerun generate with the same arguments to resume"
        )
    rollouts = load_chunks(path, meta)
    sel = read_selection(path, meta, rollouts)
    out: dict[str, Any] = {k: v[sel] for k, v in rollouts.items()}
    if features:
        fmeta = read_features_sidecar(path)
        if fmeta is not None and fmeta["status"] == "complete":
            check_features_selection(path, fmeta, meta)
            out.update(load_feature_chunks(path, fmeta, n=len(sel)))
    out["action"] = meta["action"]
    return out


def read_features_sidecar(path: Path) -> dict[str, Any] | None:
    side = path / FEATURES_SIDECAR
    if not side.exists():
        # features.json is written before any feature chunk and removed first on overwrite, so
        # chunks without it are leftovers of an interrupted overwrite: ignored, and removed by
        # the next add_features.
        return None
    try:
        fmeta = rio.read_json(side)
    except (OSError, ValueError) as e:
        raise CorruptDatasetError(f"{path}: {FEATURES_SIDECAR} is corrupt ({e})") from e
    if not isinstance(fmeta, dict) or not {"status", "batch", "n", "chunks", "selection_sha256"} <= set(fmeta):
        raise CorruptDatasetError(f"{path}: {FEATURES_SIDECAR} lacks required keys")
    return fmeta


def check_features_selection(path: Path, fmeta: Mapping[str, Any], meta: Mapping[str, Any]) -> None:
    if fmeta["selection_sha256"] != meta.get("selection", {}).get("sha256"):
        raise CorruptDatasetError(f"{path}: features were computed for a different selection")


def load_feature_chunks(path: Path, fmeta: Mapping[str, Any], n: int) -> dict[str, np.ndarray]:
    fdir = path / FEATURES
    done = chunk_indices(fdir)
    if len(done) != fmeta["chunks"] or fmeta["n"] != n:
        raise CorruptDatasetError(
            f"{path}: features sidecar records {fmeta['chunks']} chunks for {fmeta['n']} samples, "
            f"found {len(done)} chunks for {n} samples (truncated features)"
        )
    parts, schema = [], None
    for k in done:
        arrays, _ = read_chunk(chunk_path(fdir, k))
        check_schema(str(chunk_path(fdir, k)), schema_of(arrays), schema)
        schema = schema or schema_of(arrays)
        parts.append(arrays)
    out = concat(parts)
    if any(len(a) != n for a in out.values()):
        raise CorruptDatasetError(f"{path}: feature arrays do not have {n} rows")
    return out
