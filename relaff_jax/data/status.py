"""What state a dataset's generated data and its features are in, without changing anything.

Takes a dataset directory and what the caller expects there; gives ``(state, why)`` with
state one of ``absent`` (nothing there yet), ``partial`` (resumable, not finished),
``complete`` (finished, every chunk and the selection verified), ``stale`` (made with other
settings: regenerate, or recompute the features with ``overwrite=True``) or ``corrupt``
(damaged on disk; ``why`` names what). A folder that is not a relaff dataset is still a
``ForeignDirectoryError``: there is nothing to regenerate in someone else's folder.
"""
from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path
from typing import Any, Mapping

from relaff_jax.data.layout import FEATURES, FEATURES_SIDECAR, LOCK, SIDECAR, jsonable_config
from relaff_jax.data.errors import CorruptDatasetError
from relaff_jax.data.load import load_dataset, load_feature_chunks, load_rollouts, read_features_sidecar
from relaff_jax.data.store import chunk_indices, chunk_path, mismatch, read_chunk, read_sidecar

from relaff_jax import io as rio
from relaff_jax.data.store import CHUNKS, SELECTION  # the layout names the store reads

STATES = ("absent", "partial", "complete", "stale", "corrupt")
FEATURE_KEYS = ("batch", "config", "n", "selection_sha256")
# What a finished dataset looked like when it was verified: its small files' sha256 and every
# chunk file's size and mtime (``write_manifest``). A status that finds the folder unchanged
# since then answers from it without reading a chunk; any difference, or no manifest (a
# dataset from before it), and the status verifies every chunk as it always did.
MANIFEST = "status_manifest.json"
MANIFEST_VERSION = 1


def _file_sha(p: Path) -> str | None:
    try:
        return hashlib.sha256(p.read_bytes()).hexdigest()
    except FileNotFoundError:
        return None


def _tree(d: Path) -> dict[str, list[int]]:
    """``{relative path: [size, mtime_ns]}`` of every file under ``d`` (none: {})."""
    out = {}
    for root, _, names in os.walk(d):
        for n in names:
            st = os.stat(os.path.join(root, n))
            out[os.path.relpath(os.path.join(root, n), d)] = [st.st_size, st.st_mtime_ns]
    return dict(sorted(out.items()))


def _identity(path: Path, part: str) -> dict[str, Any]:
    """What the ``part`` ("data": sidecar, selection, chunks; "features": features.json and
    its chunks) of the dataset at ``path`` is on disk now, without reading a chunk."""
    if part == "data":
        return {SIDECAR: _file_sha(path / SIDECAR), SELECTION: _file_sha(path / SELECTION), CHUNKS: _tree(path / CHUNKS)}
    return {FEATURES_SIDECAR: _file_sha(path / FEATURES_SIDECAR), FEATURES: _tree(path / FEATURES)}


def write_manifest(path: str | os.PathLike, fingerprint: Mapping[str, Any] | None = None) -> None:
    """Record the finished dataset at ``path`` as it is now (call it right after generation or
    feature computation finished and verified it): the identity of its data part, of its
    features part once their ``features.json`` says complete, and ``fingerprint`` (what the
    experiment fingerprints of these features, ``learn.datasets.fingerprint`` per space) to
    be returned by ``manifest_fingerprint`` while both parts are unchanged."""
    path = Path(path)
    fmeta = read_features_sidecar(path)
    feats = _identity(path, "features") if fmeta is not None and fmeta.get("status") == "complete" else None
    rio.atomic_write_json(path / MANIFEST, {"version": MANIFEST_VERSION, "data": _identity(path, "data"),
                                            "features": feats, "fingerprint": dict(fingerprint or {}) if feats else None})


def _unchanged(path: Path, part: str) -> dict[str, Any] | None:
    """The manifest of ``path`` if its ``part`` is exactly as recorded, else None."""
    try:
        rec = rio.read_json(path / MANIFEST)
    except (OSError, ValueError):
        return None
    if not isinstance(rec, dict) or rec.get("version") != MANIFEST_VERSION or not rec.get(part):
        return None
    return rec if rec[part] == _identity(path, part) else None


def _rows_unread(cdir: Path, done: list[int], field: str | None) -> int | None:
    """Rows of ``field`` in the chunks ``done`` of ``cdir`` from their ``meta.json`` alone (0
    if ``field`` is None), or None when a chunk's metadata is missing or unreadable (the caller
    then reads the chunks, for the exact error). The resume that continues a partial dataset or
    its features reads and verifies every chunk, so the status of one does not."""
    rows = 0
    for k in done:
        p = chunk_path(cdir, k)
        try:
            spec = rio.read_json(p / "meta.json")["arrays"]
            rows += int(spec[field]["shape"][0]) if field else 0
        except (OSError, ValueError, KeyError, TypeError, IndexError):
            return None
        if not isinstance(spec, dict) or not (p / "arrays").is_dir():
            return None
    return rows


def manifest_fingerprint(path: str | os.PathLike) -> dict[str, str] | None:
    """``{space: sha256}`` recorded for the dataset's labels and features while neither its data
    nor its features changed since; None when it cannot be vouched for (compute it)."""
    path = Path(path)
    rec = _unchanged(path, "features")
    if rec is None or not rec.get("fingerprint") or _unchanged(path, "data") is None:
        return None
    return rec["fingerprint"]


def dataset_status(path: str | os.PathLike, expected: Mapping[str, Any] | None = None, *,
                   verify: bool = True) -> tuple[str, str]:
    """State of the generated data at ``path``.

    expected: sidecar values the caller would generate with, e.g. ``{"action": "lift",
        "n_samples": 10000, "seed": 0, "batch": 256, "config": {...}}`` (any sidecar keys;
        compared after a JSON round trip, so tuples match lists). A difference is ``stale``.
    verify: read and verify every chunk (and, once complete, the selection index); damage is
    ``corrupt``. False (``relaff reproduce --status``): a complete dataset unchanged since its
    ``write_manifest`` (same small files, same chunk file sizes and mtimes) and a partial one
    (rows counted from its chunks' ``meta.json``) are not read; anything else is verified.
    """
    path = Path(path)
    if not path.exists():
        return "absent", f"{path} does not exist"
    if path.is_dir() and not any(p.name != LOCK for p in path.iterdir()):
        return "absent", f"{path} is empty"
    try:
        meta = read_sidecar(path)
    except CorruptDatasetError as e:
        return "corrupt", str(e)
    wanted = jsonable_config(expected)
    diff = mismatch(meta, wanted, sorted(wanted))
    if diff:
        return "stale", "; ".join(diff)
    try:
        if meta["status"] != "complete":
            done = chunk_indices(path / CHUNKS)
            n = None if verify or len(done) < meta["counts"]["chunks"] else _rows_unread(path / CHUNKS, done, "label")
            n = len(load_rollouts(path)["label"]) if n is None else n
            return "partial", f"{n} rollouts in {meta['counts']['chunks']} chunks, generation not finished"
        if verify or _unchanged(path, "data") is None:
            n = len(load_dataset(path, features=False)["label"])
        else:  # verified when it was recorded, unchanged since (``write_manifest``)
            n = meta["n_samples"]
    except CorruptDatasetError as e:
        return "corrupt", str(e)
    return "complete", f"{n} samples from {meta['counts']['rollouts']} rollouts"


def features_status(path: str | os.PathLike, batch: int, config: Mapping[str, Any] | None = None, *,
                    verify: bool = True) -> tuple[str, str]:
    """State of the features of the dataset at ``path`` for ``add_features(path, fn, batch,
    config_dict=config)``: ``absent`` (none, or the dataset is not finished), ``partial``,
    ``complete``, ``stale`` (other batch, config or selection) or ``corrupt`` (a damaged
    feature chunk or ``features.json``; ``add_features(..., overwrite=True)`` recomputes).
    verify: read and verify every feature chunk. False: complete features unchanged since
    ``write_manifest`` and partial ones (chunk metadata present) are not read.
    """
    path = Path(path)
    try:
        meta = read_sidecar(path)
        if meta["status"] != "complete":
            return "absent", "dataset generation not finished"
        fmeta = read_features_sidecar(path)
    except CorruptDatasetError as e:
        return "corrupt", str(e)
    if fmeta is None:
        return "absent", "no features computed"
    n = meta["n_samples"]
    header = {"batch": batch, "config": jsonable_config(config), "n": n,
              "selection_sha256": meta.get("selection", {}).get("sha256")}
    diff = mismatch(fmeta, header, FEATURE_KEYS)
    if diff:
        return "stale", "; ".join(diff)
    try:
        if fmeta["status"] != "complete":
            fdir = path / FEATURES
            done = chunk_indices(fdir)
            if verify or _rows_unread(fdir, done, None) is None:
                for k in done:
                    read_chunk(chunk_path(fdir, k))
            return "partial", f"{len(done)} of {math.ceil(n / batch)} feature chunks"
        if verify or _unchanged(path, "features") is None:
            load_feature_chunks(path, fmeta, n)
    except CorruptDatasetError as e:
        return "corrupt", str(e)
    return "complete", f"features of {n} samples in {fmeta['chunks']} chunks"


def generation_progress(path: str | os.PathLike, n_samples: int) -> float:
    """Fraction of a dataset's generation done, from its sidecar alone (cheap enough for a
    progress line): 1 when complete, else the samples of a balanced selection in hand
    (``counts.in_hand``, negatives matched included) out of N; a sidecar written before that
    count existed gives the positives found towards the N/2 it needs."""
    path = Path(path)
    if not (path / SIDECAR).exists():
        return 0.0
    meta = read_sidecar(path)
    if meta.get("status") == "complete":
        return 1.0
    if "in_hand" in meta["counts"]:
        return min(meta["counts"]["in_hand"], n_samples) / max(n_samples, 1)
    half = max(n_samples // 2, 1)
    return min(meta["counts"]["positives"], half) / half


def features_progress(path: str | os.PathLike, n_samples: int, batch: int) -> float:
    """Fraction of a dataset's feature chunks written (from ``features.json``)."""
    fmeta = read_features_sidecar(Path(path)) if (Path(path) / FEATURES_SIDECAR).exists() else None
    if fmeta is None:
        return 0.0
    return min(fmeta["chunks"] / math.ceil(n_samples / batch), 1.0)
