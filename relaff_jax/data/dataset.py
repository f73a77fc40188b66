"""Balanced, resumable datasets of labelled action rollouts (paper section IV-D).

Takes a *rollout function* ``rollout_fn(key, batch_size) -> dict[str, array]`` that simulates
one batch of scenes for one action and labels them; gives a dataset directory holding every
rollout (in orbax-checkpoint chunks) and a balanced selection of N of them: N/2 positives
drawn uniformly, N/2 negatives drawn so that their distribution of the distance between the
two objects' centres of gravity (COG) matches the positives' (paper IV-D: otherwise a
classifier learns "small distance => positive" and never the on-top/inside relation).

Public API::

    generate_dataset(out_dir, action, n_samples, rollout_fn, seed, batch, config_dict) -> summary
    load_dataset(dir)  -> dict of (N, ...) arrays of the selected samples (+ features, + action)
    load_rollouts(dir) -> dict of (R, ...) arrays of every rollout (+ ``selected`` mask)
    add_features(dir, compute_fn, batch)  -> attaches (N, ...) feature arrays (pca, rhf, ...)
    info(dir) -> counts and positive rates;   register_cli(sub) adds ``relaff info DIR [--json]``

Every rollout dict holds, with leading axis ``B`` (the batch size): ``label`` (B,) bool,
``relation`` (B,) str in ``RELATIONS`` (or int codes into ``RELATIONS``), ``cog_distance``
(B,) float metres, ``toy`` and ``other`` (B,) object names (or int ids into
``object_names``), plus any other numeric or string per-sample arrays (poses, pair index,
per-sample seed, ...). Strings are stored as int32 codes with a per-chunk vocabulary (orbax's
tensorstore backend has no string dtype) and come back as numpy ``str`` arrays. The driver
adds ``rollout`` (B,) int64, the global rollout index ``chunk * batch + i``.

Determinism: chunk ``k`` is simulated with ``jax.random.fold_in(PRNGKey(seed), k)``, the
generator stops after the first chunk count at which a balanced selection exists, and the
selection is a function of the stored labels/distances and ``seed`` only; so a run that is
killed and rerun gives the same chunks and the same dataset as one that never stopped.
Layout, selection scheme and error cases: ``docs/datasets.md``.
"""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.metadata
import json
import math
import os
import platform
import re
import shutil
import sys
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import to_dict

from relaff_jax.constants import ACTIONS, RELATIONS  # noqa: F401 (re-exported)
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
_CHUNK_RE = re.compile(r"^chunk_(\d{6})$")
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_SELECT_SALT = 0x5E1EC7  # separates the selection's RNG stream from anything else seeded by `seed`


class DatasetError(ValueError):
    """Bad dataset input or a dataset directory that cannot be used."""


class ForeignDirectoryError(DatasetError):
    """The directory exists but is not a relaff dataset."""


class DatasetMismatchError(DatasetError):
    """Resuming a dataset with a different action, seed, batch, N or config."""


class CorruptDatasetError(DatasetError):
    """A missing, truncated or corrupt chunk, sidecar or index."""


class RolloutCapError(DatasetError):
    """The rollout cap was reached before a balanced selection existed."""


@dataclasses.dataclass(frozen=True)
class DatasetConfig:
    """How many rollouts at most and how negatives are matched to positives.

    max_rollouts: cap on simulated rollouts (rounded up to whole chunks); the paper's
        1.5M simulations over nine actions are ~170k per action. Not part of the resume
        check, so a run stopped by the cap can be rerun with a larger one.
    distance_bins: equal-width COG-distance bins spanning the selected positives' range.
    borrow_fraction: generation stops once at most this fraction of the negatives has to be
        borrowed from outside its distance bin (0 = exact histogram match). At the cap any
        amount is accepted, with a warning, and the number is recorded.
    """

    max_rollouts: int = 200_000
    distance_bins: int = 20
    borrow_fraction: float = 0.01


# ----------------------------------------------------------------------------- selection


@dataclasses.dataclass(frozen=True)
class Selection:
    """A balanced selection. ``selected``: (N,) sorted rollout indices."""

    selected: np.ndarray
    n_positive: int
    n_negative: int
    bin_edges: np.ndarray
    positive_bin_counts: np.ndarray
    negative_bin_counts: np.ndarray
    borrowed: int


def _bin_index(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin of each value for bins [e0,e1), ..., [e_{m-1}, e_m] (last closed); -1 outside."""
    nb = len(edges) - 1
    idx = np.searchsorted(edges, x, side="right") - 1
    idx = np.where(x == edges[-1], nb - 1, idx)
    return np.where((x < edges[0]) | (x > edges[-1]), -1, idx)


def _allocate(counts: np.ndarray, total: int) -> np.ndarray:
    """Scale integer ``counts`` to sum to ``total`` (largest remainder, ties to lower bins)."""
    exact = counts * (total / counts.sum())
    base = np.floor(exact).astype(np.int64)
    rest = total - int(base.sum())
    order = np.lexsort((np.arange(len(counts)), -(exact - base)))
    base[order[:rest]] += 1
    return base


def select_balanced(
    label: np.ndarray, cog_distance: np.ndarray, n: int, seed: int, bins: int = 20
) -> Selection | None:
    """Pick ``n`` rollouts: ``n // 2`` positives uniformly, the rest COG-distance-matched negatives.

    label: (R,) bool; cog_distance: (R,) float. Returns ``None`` when there are fewer than
    ``n // 2`` positives or ``n - n // 2`` negatives. Scheme (docs/datasets.md):
    1. positives: ``n_pos`` drawn uniformly without replacement;
    2. ``bins`` equal-width bins over [min, max] of the selected positives' distances; each
       bin's negative quota is its positive count (scaled by largest remainder when N is odd);
    3. each bin's quota is drawn uniformly from the negatives in that bin;
    4. a bin with too few negatives takes all it has, and its deficit is filled, bins in
       order, with the remaining negatives nearest to the bin's interval (random tie-break);
       their number is ``borrowed``.
    All draws come from one numpy Generator seeded by ``(seed, salt)``.
    """
    label = np.asarray(label, bool)
    dist = np.asarray(cog_distance, np.float64)
    n_pos, n_neg = n // 2, n - n // 2
    pos, neg = np.flatnonzero(label), np.flatnonzero(~label)
    if len(pos) < n_pos or len(neg) < n_neg:
        return None
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), _SELECT_SALT]))
    sel_pos = np.sort(rng.choice(pos, n_pos, replace=False))
    d_pos = dist[sel_pos]
    edges = np.linspace(d_pos.min(), d_pos.max(), bins + 1)
    pos_counts = np.bincount(_bin_index(d_pos, edges), minlength=bins)
    quota = pos_counts.copy() if n_neg == n_pos else _allocate(pos_counts, n_neg)
    neg_bin = _bin_index(dist[neg], edges)
    taken = np.zeros(len(neg), bool)
    deficit = np.zeros(bins, np.int64)
    for b in range(bins):
        cand = np.flatnonzero(neg_bin == b)
        k = min(int(quota[b]), len(cand))
        taken[rng.choice(cand, k, replace=False)] = True
        deficit[b] = quota[b] - k
    neg_counts = quota - deficit
    for b in np.flatnonzero(deficit):
        pool = np.flatnonzero(~taken)
        x = dist[neg[pool]]
        gap = np.maximum(np.maximum(edges[b] - x, x - edges[b + 1]), 0.0)
        order = np.lexsort((rng.random(len(pool)), gap))
        taken[pool[order[: deficit[b]]]] = True
    selected = np.sort(np.concatenate([sel_pos, neg[taken]]))
    return Selection(selected, n_pos, n_neg, edges, pos_counts, neg_counts, int(deficit.sum()))


# ----------------------------------------------------------------------------- validation


def _check_action(action: Any) -> str:
    if action not in ACTIONS:
        raise DatasetError(f"unknown action {action!r}; valid actions: {', '.join(ACTIONS)}")
    return action


def _check_int(name: str, value: Any, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise DatasetError(f"{name} must be an integer, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise DatasetError(f"{name} must be {rng}, got {value}")
    return int(value)


def _check_dataset_config(cfg: DatasetConfig) -> None:
    _check_int("max_rollouts", cfg.max_rollouts, 1)
    _check_int("distance_bins", cfg.distance_bins, 1)
    if not 0.0 <= float(cfg.borrow_fraction) <= 1.0:
        raise DatasetError(f"borrow_fraction must be in [0, 1], got {cfg.borrow_fraction}")


def _as_strings(name: str, a: np.ndarray) -> np.ndarray:
    if a.dtype.kind == "S":
        return np.char.decode(a, "utf-8").astype(str)
    if a.dtype.kind == "O":
        if not all(isinstance(v, str) for v in a.ravel()):
            raise DatasetError(f"{name}: object array must hold only str values")
        return a.astype(str)
    return a


def _standardize(out: Any, batch: int, object_names: Sequence[str] | None) -> dict[str, np.ndarray]:
    """Check a rollout_fn result and bring it to storage types (strings as numpy str)."""
    if not isinstance(out, Mapping):
        raise DatasetError(f"rollout_fn must return a dict of arrays, got {type(out).__name__}")
    missing = [k for k in REQUIRED_FIELDS if k not in out]
    if missing:
        raise DatasetError(f"rollout_fn result lacks required field(s) {missing}")
    arrays: dict[str, np.ndarray] = {}
    for name, value in out.items():
        if not isinstance(name, str) or not _NAME_RE.match(name):
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


def _schema(arrays: Mapping[str, np.ndarray]) -> dict[str, list]:
    return {k: ["str" if a.dtype.kind == "U" else a.dtype.str, list(a.shape[1:])] for k, a in arrays.items()}


def _check_schema(where: str, schema: Mapping[str, list], ref: Mapping[str, list] | None) -> None:
    if ref is None:
        return
    if set(schema) != set(ref):
        raise DatasetError(
            f"{where}: fields {sorted(schema)} differ from earlier chunks' {sorted(ref)}"
        )
    for k in ref:
        if list(schema[k]) != list(ref[k]):
            raise DatasetError(f"{where}: field {k!r} is {schema[k]}, earlier chunks {ref[k]}")


# ----------------------------------------------------------------------------- chunk storage


_CHECKPOINTER = None


def _checkpointer():
    # One synchronous PyTree checkpointer: ~40 ms per save, ~10 ms per restore of a chunk.
    global _CHECKPOINTER
    if _CHECKPOINTER is None:
        import orbax.checkpoint as ocp

        _CHECKPOINTER = ocp.PyTreeCheckpointer()
    return _CHECKPOINTER


def _sha(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def _write_chunk(path: Path, arrays: Mapping[str, np.ndarray], extra: Mapping[str, Any]) -> None:
    """Write one chunk dir (orbax tree ``arrays/`` + ``meta.json``) atomically to ``path``."""
    tree: dict[str, np.ndarray] = {}
    vocab: dict[str, list[str]] = {}
    for k, a in arrays.items():
        if a.dtype.kind == "U":
            names, codes = np.unique(a, return_inverse=True)
            vocab[k] = names.tolist()
            a = codes.reshape(a.shape).astype(np.int32)
        tree[k] = np.ascontiguousarray(a)
    meta = dict(extra)
    meta["arrays"] = {k: {"dtype": a.dtype.str, "shape": list(a.shape), "sha256": _sha(a)} for k, a in tree.items()}
    meta["vocab"] = vocab
    with rio.atomic_directory(path) as tmp:
        _checkpointer().save(str((tmp / "arrays").resolve()), tree)
        rio.atomic_write_json(tmp / "meta.json", meta)


def _read_chunk(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read and verify one chunk; strings decoded. Raises CorruptDatasetError."""
    try:
        meta = rio.read_json(path / "meta.json")
    except (OSError, ValueError) as e:
        raise CorruptDatasetError(f"chunk {path}: metadata missing or corrupt ({e})") from e
    if not (path / "arrays").is_dir():
        raise CorruptDatasetError(f"chunk {path}: orbax cannot read it (its arrays/ checkpoint is missing)")
    try:
        tree = _checkpointer().restore(str((path / "arrays").resolve()))
    except Exception as e:  # orbax/tensorstore raise many types on damaged files
        raise CorruptDatasetError(f"chunk {path}: orbax cannot read it ({type(e).__name__}: {e})") from e
    spec = meta.get("arrays", {})
    if not isinstance(tree, dict) or set(tree) != set(spec):
        raise CorruptDatasetError(f"chunk {path}: stored arrays do not match its metadata")
    out: dict[str, np.ndarray] = {}
    for k, s in spec.items():
        a = np.asarray(tree[k])
        if a.dtype.str != s["dtype"] or list(a.shape) != s["shape"] or _sha(a) != s["sha256"]:
            raise CorruptDatasetError(f"chunk {path}: array {k!r} is corrupt (checksum/shape mismatch)")
        if k in meta.get("vocab", {}):
            names = np.asarray(meta["vocab"][k], dtype=str)
            if a.size and (a.min() < 0 or a.max() >= len(names)):
                raise CorruptDatasetError(f"chunk {path}: codes of {k!r} outside its vocabulary")
            a = names[a]
        out[k] = a
    return out, meta


def _chunk_indices(cdir: Path) -> list[int]:
    """Sorted indices of finished chunks in ``cdir``; a gap is a truncated dataset."""
    if not cdir.is_dir():
        return []
    found = sorted(int(m.group(1)) for p in cdir.iterdir() if (m := _CHUNK_RE.match(p.name)) and p.is_dir())
    if found != list(range(len(found))):
        missing = sorted(set(range(found[-1] + 1)) - set(found))
        raise CorruptDatasetError(f"{cdir}: chunk(s) {missing} missing before later chunks (truncated)")
    return found


def _chunk_path(cdir: Path, k: int) -> Path:
    return cdir / f"chunk_{k:06d}"


def _clean_tmp(*dirs: Path) -> list[str]:
    """Remove leftovers of killed atomic writes (``.NAME.XXXX.tmp`` files/dirs)."""
    removed = []
    for d in dirs:
        if not d.is_dir():
            continue
        for p in d.iterdir():
            if p.name.startswith(".") and p.name.endswith(".tmp"):
                shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
                removed.append(str(p))
    return removed


def _concat(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    if not parts:
        return {}
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


# ----------------------------------------------------------------------------- directories


def _jsonable(obj: Any) -> Any:
    return json.loads(json.dumps(obj, sort_keys=True, default=rio._json_default))


def _versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {"python": platform.python_version()}
    for pkg in ("relaff_jax", "numpy", "jax", "jaxlib", "mujoco", "mujoco-mjx", "orbax-checkpoint"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def _read_sidecar(path: Path) -> dict[str, Any]:
    """The dataset sidecar of ``path``; errors for a missing, foreign or corrupt directory."""
    if not path.exists():
        raise DatasetError(f"{path}: no such dataset directory")
    if not path.is_dir():
        raise DatasetError(f"{path}: not a directory")
    side = path / SIDECAR
    if not side.is_file():
        if (path / CHUNKS).exists() or (path / SELECTION).exists():
            raise CorruptDatasetError(f"{path}: dataset sidecar {SIDECAR} is missing (truncated dataset)")
        raise ForeignDirectoryError(f"{path}: not a relaff dataset (no {SIDECAR})")
    try:
        meta = rio.read_json(side)
    except (OSError, ValueError) as e:
        raise CorruptDatasetError(f"{path}: sidecar {SIDECAR} is corrupt ({e})") from e
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ForeignDirectoryError(f"{path}: {SIDECAR} is not a relaff dataset sidecar")
    if meta.get("format_version") != FORMAT_VERSION:
        raise DatasetError(f"{path}: dataset format version {meta.get('format_version')} unsupported")
    for key in ("action", "n_samples", "seed", "batch", "status", "counts"):
        if key not in meta:
            raise CorruptDatasetError(f"{path}: sidecar lacks {key!r}")
    return meta


@contextlib.contextmanager
def _writer_lock(path: Path) -> Iterator[None]:
    """Exclusive advisory lock so two writers never interleave chunks in one directory."""
    import fcntl

    try:
        fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise DatasetError(f"{path}: directory is not writable ({e})") from e
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetError(f"{path}: another process is writing this dataset") from None
        yield
    finally:
        os.close(fd)


def _prepare_dir(path: Path) -> bool:
    """Make ``path`` usable for a new or resumed dataset; True if this call created it."""
    if path.exists():
        if not path.is_dir():
            raise DatasetError(f"{path}: exists and is not a directory")
        if not (path / SIDECAR).exists():
            if (path / CHUNKS).exists() or (path / SELECTION).exists():
                raise CorruptDatasetError(f"{path}: dataset sidecar {SIDECAR} is missing (truncated dataset)")
            if any(p.name != LOCK for p in path.iterdir()):
                raise ForeignDirectoryError(f"{path}: exists, is not empty and is not a relaff dataset")
        if not os.access(path, os.W_OK | os.X_OK):
            raise DatasetError(f"{path}: directory is not writable")
        return False
    try:
        path.mkdir(parents=True)
    except OSError as e:
        raise DatasetError(f"{path}: cannot create dataset directory ({e})") from e
    return True


def _mismatch(stored: Mapping[str, Any], wanted: Mapping[str, Any], keys: Sequence[str]) -> list[str]:
    def short(v: Any) -> str:
        s = json.dumps(v, sort_keys=True)
        return s if len(s) <= 80 else s[:77] + "..."

    return [f"{k}: stored {short(stored.get(k))}, requested {short(wanted.get(k))}" for k in keys if stored.get(k) != wanted.get(k)]


# ----------------------------------------------------------------------------- generation


def generate_dataset(
    out_dir: str | os.PathLike,
    action: str,
    n_samples: int,
    rollout_fn: Callable[[Any, int], Mapping[str, Any]],
    seed: int,
    batch: int,
    config_dict: Mapping[str, Any] | None = None,
    progress: bool = True,
    *,
    dataset_config: DatasetConfig | None = None,
    object_names: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Simulate rollouts in chunks until ``n_samples`` balanced samples exist; write the dataset.

    out_dir: new, empty or resumable dataset directory.
    rollout_fn(key, batch) -> dict of (batch, ...) arrays (see module docstring); called with
        ``jax.random.fold_in(jax.random.PRNGKey(seed), k)`` for chunk ``k``, always with
        ``batch`` as its second argument (static shapes: one compile).
    config_dict: the action/physics config, stored in the sidecar and compared on resume.
    object_names: table for int ``toy``/``other`` ids, if the rollout_fn returns ids.
    Returns a summary: ``rollouts`` simulated, ``chunks``, ``positives``/``positive_rate``
    over all rollouts, ``borrowed`` negatives, ``new_chunks`` simulated by this call.
    """
    _check_action(action)
    n_samples = _check_int("n_samples", n_samples, 2)
    batch = _check_int("batch", batch, 1)
    seed = _check_int("seed", seed, 0, 2**32 - 1)
    if not callable(rollout_fn):
        raise DatasetError("rollout_fn must be callable")
    dcfg = dataset_config or DatasetConfig()
    _check_dataset_config(dcfg)
    try:
        config = _jsonable(dict(config_dict or {}))
    except (TypeError, ValueError) as e:
        raise DatasetError(f"config_dict is not JSON serialisable ({e})") from e
    header = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "action": action,
        "n_samples": n_samples,
        "seed": seed,
        "batch": batch,
        "config": config,
        "object_names": list(object_names) if object_names is not None else None,
        "selection_scheme": {"distance_bins": dcfg.distance_bins, "borrow_fraction": dcfg.borrow_fraction},
    }
    path = Path(out_dir)
    created = _prepare_dir(path)
    try:
        with _writer_lock(path):
            return _generate_locked(path, header, rollout_fn, dcfg, object_names, progress)
    except BaseException:
        # A dataset this call created but never gave a chunk leaves nothing behind.
        if created and not _chunk_dirs_exist(path):
            shutil.rmtree(path, ignore_errors=True)
        raise


def _chunk_dirs_exist(path: Path) -> bool:
    cdir = path / CHUNKS
    return cdir.is_dir() and any(_CHUNK_RE.match(p.name) for p in cdir.iterdir())


def _generate_locked(path, header, rollout_fn, dcfg, object_names, progress) -> dict[str, Any]:
    cdir = path / CHUNKS
    _clean_tmp(path, cdir)
    if (path / SIDECAR).exists():
        meta = _read_sidecar(path)
        diff = _mismatch(meta, header, ("action", "n_samples", "seed", "batch", "config", "object_names", "selection_scheme"))
        if diff:
            raise DatasetMismatchError(f"{path}: holds a different dataset; " + "; ".join(diff))
        if meta["status"] == "complete":
            load_dataset(path)  # verifies chunks and index
            return _summary(meta, new_chunks=0)
    else:
        meta = dict(header, status="generating", counts={"chunks": 0, "rollouts": 0, "positives": 0})
        meta["versions"] = _versions()
        meta["dataset_config"] = to_dict(dcfg)
        rio.atomic_write_json(path / SIDECAR, meta)
    meta["dataset_config"] = to_dict(dcfg)  # the cap may change between runs; record the last
    action, n, seed, batch = meta["action"], meta["n_samples"], meta["seed"], meta["batch"]

    done = _chunk_indices(cdir)
    if len(done) < meta["counts"]["chunks"]:
        raise CorruptDatasetError(
            f"{path}: sidecar records {meta['counts']['chunks']} chunks but only {len(done)} exist (truncated)"
        )
    labels, dists, schema = [], [], None
    for k in done:
        arrays, _ = _read_chunk(_chunk_path(cdir, k))
        _check_rollout_ids(_chunk_path(cdir, k), arrays, k, batch)
        arrays.pop("rollout")
        _check_schema(f"chunk {k}", _schema(arrays), schema)
        schema = schema or _schema(arrays)
        labels.append(arrays["label"])
        dists.append(arrays["cog_distance"])
    k0 = len(done)
    max_chunks = math.ceil(dcfg.max_rollouts / batch)
    bar = _progress_bar(progress, n // 2, f"{action} positives")
    bar.update(min(int(sum(l.sum() for l in labels)), n // 2))
    k = k0
    try:
        while True:
            lab = np.concatenate(labels) if labels else np.zeros(0, bool)
            dist = np.concatenate(dists) if dists else np.zeros(0)
            sel = select_balanced(lab, dist, n, seed, dcfg.distance_bins)
            at_cap = k >= max_chunks
            if sel is not None and (at_cap or sel.borrowed <= dcfg.borrow_fraction * sel.n_negative):
                break
            if at_cap:
                rate = lab.mean() if lab.size else float("nan")
                raise RolloutCapError(
                    f"{action}: rollout cap reached (max_rollouts={dcfg.max_rollouts}, {lab.size} rollouts in "
                    f"{k} chunks) with {int(lab.sum())} positives and {int((~lab).sum())} negatives, "
                    f"positive rate {rate:.2%}; {n} samples need {n // 2} positives and {n - n // 2} "
                    f"negatives. Rerun with a larger max_rollouts to continue from the chunks kept in {cdir}."
                )
            import jax

            key = jax.random.fold_in(jax.random.PRNGKey(seed), k)
            arrays = _standardize(rollout_fn(key, batch), batch, object_names)
            _check_schema(f"chunk {k} from rollout_fn", _schema(arrays), schema)
            schema = schema or _schema(arrays)
            arrays["rollout"] = k * batch + np.arange(batch, dtype=np.int64)
            _write_chunk(_chunk_path(cdir, k), arrays, {"chunk": k, "batch": batch, "positives": int(arrays["label"].sum())})
            labels.append(arrays["label"])
            dists.append(arrays["cog_distance"])
            k += 1
            npos = int(sum(l.sum() for l in labels))
            meta["counts"] = {"chunks": k, "rollouts": k * batch, "positives": npos}
            rio.atomic_write_json(path / SIDECAR, meta)
            bar.update(min(npos, n // 2) - bar.n)
            bar.set_postfix(rollouts=k * batch, pos_rate=f"{npos / (k * batch):.1%}")
    finally:
        bar.close()
    if sel.borrowed > dcfg.borrow_fraction * sel.n_negative:
        warnings.warn(
            f"{action}: rollout cap reached; {sel.borrowed} of {sel.n_negative} negatives come from "
            f"outside their COG-distance bin (recorded in {SELECTION})",
            stacklevel=2,
        )
    index = {
        "n": n,
        "n_positive": sel.n_positive,
        "n_negative": sel.n_negative,
        "seed": seed,
        "chunks": k,
        "rollouts": k * batch,
        "bin_edges": sel.bin_edges.tolist(),
        "positive_bin_counts": sel.positive_bin_counts.tolist(),
        "negative_bin_counts": sel.negative_bin_counts.tolist(),
        "borrowed": sel.borrowed,
        "at_cap": bool(k >= max_chunks),
        "selected": sel.selected.tolist(),
    }
    rio.atomic_write_json(path / SELECTION, index)
    meta["status"] = "complete"
    meta["selection"] = {key: index[key] for key in ("n", "n_positive", "n_negative", "chunks", "rollouts", "borrowed", "at_cap")}
    meta["selection"]["sha256"] = _sha(sel.selected.astype(np.int64))
    rio.atomic_write_json(path / SIDECAR, meta)
    summary = _summary(meta, new_chunks=k - k0)
    if progress:
        print(
            f"{action}: {n} samples selected from {summary['rollouts']} rollouts ({k} chunks, "
            f"{k - k0} new), positive rate {summary['positive_rate']:.2%}, "
            f"{sel.borrowed} negatives borrowed across distance bins",
            file=sys.stderr,
        )
    return summary


def _summary(meta: Mapping[str, Any], new_chunks: int) -> dict[str, Any]:
    c = meta["counts"]
    return {
        "action": meta["action"],
        "n": meta["n_samples"],
        "rollouts": c["rollouts"],
        "chunks": c["chunks"],
        "positives": c["positives"],
        "positive_rate": c["positives"] / c["rollouts"] if c["rollouts"] else float("nan"),
        "borrowed": meta.get("selection", {}).get("borrowed"),
        "new_chunks": new_chunks,
    }


def _check_rollout_ids(where: Path, arrays: Mapping[str, np.ndarray], k: int, batch: int) -> None:
    ids = arrays.get("rollout")
    if ids is None or not np.array_equal(ids, k * batch + np.arange(batch)):
        raise CorruptDatasetError(f"chunk {where}: rollout ids are not those of chunk {k} (renamed or mixed chunk)")


class _NoBar:
    n = 0

    def update(self, k: int) -> None:
        self.n += k

    def set_postfix(self, **kw: Any) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar(progress: bool, total: int, desc: str, unit: str = "pos"):
    if not progress:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True)


# ----------------------------------------------------------------------------- loading


def _load_chunks(path: Path, meta: Mapping[str, Any]) -> dict[str, np.ndarray]:
    cdir = path / CHUNKS
    done = _chunk_indices(cdir)
    want = meta["counts"]["chunks"]
    if len(done) < want or (meta["status"] == "complete" and len(done) != want):
        raise CorruptDatasetError(f"{path}: sidecar records {want} chunks, found {len(done)} (truncated dataset)")
    parts, schema = [], None
    for k in done:
        arrays, _ = _read_chunk(_chunk_path(cdir, k))
        _check_rollout_ids(_chunk_path(cdir, k), arrays, k, meta["batch"])
        _check_schema(f"{_chunk_path(cdir, k)}", _schema(arrays), schema)
        schema = schema or _schema(arrays)
        parts.append(arrays)
    if not parts:  # nothing simulated yet: empty required fields keep info() working
        return {
            "label": np.zeros(0, bool), "relation": np.zeros(0, str), "cog_distance": np.zeros(0),
            "toy": np.zeros(0, str), "other": np.zeros(0, str), "rollout": np.zeros(0, np.int64),
        }
    return _concat(parts)


def _read_selection(path: Path, meta: Mapping[str, Any], rollouts: Mapping[str, np.ndarray]) -> np.ndarray:
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
        or _sha(sel) != meta.get("selection", {}).get("sha256")
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
    meta = _read_sidecar(path)
    out: dict[str, Any] = _load_chunks(path, meta)
    mask = np.zeros(len(out.get("rollout", ())), bool)
    if meta["status"] == "complete":
        mask[_read_selection(path, meta, out)] = True
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
    meta = _read_sidecar(path)
    if meta["status"] != "complete":
        c = meta["counts"]
        raise DatasetError(
            f"{path}: generation not finished ({c['rollouts']} rollouts in {c['chunks']} chunks so far); "
            "rerun generate with the same arguments to resume"
        )
    rollouts = _load_chunks(path, meta)
    sel = _read_selection(path, meta, rollouts)
    out: dict[str, Any] = {k: v[sel] for k, v in rollouts.items()}
    if features:
        fmeta = _read_features_sidecar(path)
        if fmeta is not None and fmeta["status"] == "complete":
            _check_features_selection(path, fmeta, meta)
            out.update(_load_feature_chunks(path, fmeta, n=len(sel)))
    out["action"] = meta["action"]
    return out


# ----------------------------------------------------------------------------- features


def _read_features_sidecar(path: Path) -> dict[str, Any] | None:
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


def _check_features_selection(path: Path, fmeta: Mapping[str, Any], meta: Mapping[str, Any]) -> None:
    if fmeta["selection_sha256"] != meta.get("selection", {}).get("sha256"):
        raise CorruptDatasetError(f"{path}: features were computed for a different selection")


def _load_feature_chunks(path: Path, fmeta: Mapping[str, Any], n: int) -> dict[str, np.ndarray]:
    fdir = path / FEATURES
    done = _chunk_indices(fdir)
    if len(done) != fmeta["chunks"] or fmeta["n"] != n:
        raise CorruptDatasetError(
            f"{path}: features sidecar records {fmeta['chunks']} chunks for {fmeta['n']} samples, "
            f"found {len(done)} chunks for {n} samples (truncated features)"
        )
    parts, schema = [], None
    for k in done:
        arrays, _ = _read_chunk(_chunk_path(fdir, k))
        _check_schema(str(_chunk_path(fdir, k)), _schema(arrays), schema)
        schema = schema or _schema(arrays)
        parts.append(arrays)
    out = _concat(parts)
    if any(len(a) != n for a in out.values()):
        raise CorruptDatasetError(f"{path}: feature arrays do not have {n} rows")
    return out


def _standardize_features(out: Any, batch: int, taken: set[str]) -> dict[str, np.ndarray]:
    if not isinstance(out, Mapping) or not out:
        raise DatasetError("compute_fn must return a non-empty dict of arrays")
    arrays = {}
    for name, value in out.items():
        if not isinstance(name, str) or not _NAME_RE.match(name):
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


def add_features(
    path: str | os.PathLike,
    compute_fn: Callable[[dict[str, np.ndarray]], Mapping[str, Any]],
    batch: int,
    progress: bool = True,
    config_dict: Mapping[str, Any] | None = None,
    *,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Compute per-sample features of a finished dataset in resumable chunks and store them.

    compute_fn(samples) -> dict of (batch, ...) numeric/bool arrays (e.g. ``pca`` (batch, 18),
    ``rhf`` (batch, 300), ``unseen`` (batch, 2) bool). ``samples`` holds the (batch, ...)
    per-sample arrays of ``load_dataset`` (no features, no ``action``); every call gets exactly
    ``batch`` samples: the last batch is padded by repeating its last sample and the padded
    rows' outputs are dropped. Feature chunk ``f`` covers selected samples
    ``[f * batch, (f + 1) * batch)``. ``config_dict`` (e.g. the perception config) is stored
    and compared on resume; a mismatch is an error unless ``overwrite`` removes the old features.
    Returns ``{"n", "chunks", "new_chunks", "features": {name: shape}}``.
    """
    path = Path(path)
    batch = _check_int("batch", batch, 1)
    if not callable(compute_fn):
        raise DatasetError("compute_fn must be callable")
    try:
        config = _jsonable(dict(config_dict or {}))
    except (TypeError, ValueError) as e:
        raise DatasetError(f"config_dict is not JSON serialisable ({e})") from e
    meta = _read_sidecar(path)
    with _writer_lock(path):
        samples = load_dataset(path, features=False)
        samples.pop("action")
        n = len(samples["label"])
        header = {"batch": batch, "config": config, "n": n, "selection_sha256": meta["selection"]["sha256"]}
        fdir, fside = path / FEATURES, path / FEATURES_SIDECAR
        _clean_tmp(path, fdir)
        fmeta = None
        try:
            fmeta = _read_features_sidecar(path)
        except CorruptDatasetError:
            if not overwrite:
                raise
        if fmeta is not None:
            diff = _mismatch(fmeta, header, ("batch", "config", "n", "selection_sha256"))
            if diff and not overwrite:
                raise DatasetMismatchError(f"{path}: holds features of another run ({'; '.join(diff)}); pass overwrite=True to recompute")
            if overwrite:
                fmeta = None
        if fmeta is None:
            _remove_features(path)
            fmeta = dict(header, status="generating", chunks=0, versions=_versions())
            rio.atomic_write_json(fside, fmeta)
        elif fmeta["status"] == "complete":
            feats = _load_feature_chunks(path, fmeta, n)
            return {"n": n, "chunks": fmeta["chunks"], "new_chunks": 0, "features": {k: list(a.shape) for k, a in feats.items()}}
        done = _chunk_indices(fdir)
        if len(done) < fmeta["chunks"]:
            raise CorruptDatasetError(f"{path}: features sidecar records {fmeta['chunks']} chunks, found {len(done)}")
        schema = None
        if done:
            _, m0 = _read_chunk(_chunk_path(fdir, 0))
            schema = {k: [s["dtype"], s["shape"][1:]] for k, s in m0["arrays"].items()}
        n_chunks = math.ceil(n / batch)
        bar = _progress_bar(progress, n, "features", unit="sample")
        bar.update(min(len(done) * batch, n))
        try:
            for f in range(len(done), n_chunks):
                lo, hi = f * batch, min((f + 1) * batch, n)
                idx = np.minimum(np.arange(lo, lo + batch), hi - 1)  # pad by repeating the last sample
                out = compute_fn({k: v[idx] for k, v in samples.items()})
                arrays = _standardize_features(out, batch, set(samples))
                arrays = {k: a[: hi - lo] for k, a in arrays.items()}
                _check_schema(f"feature chunk {f}", _schema(arrays), schema)
                schema = schema or _schema(arrays)
                _write_chunk(_chunk_path(fdir, f), arrays, {"chunk": f, "batch": batch, "start": lo, "stop": hi})
                fmeta["chunks"] = f + 1
                rio.atomic_write_json(fside, fmeta)
                bar.update(hi - lo)
        finally:
            bar.close()
        feats = _load_feature_chunks(path, fmeta, n)
        fmeta["status"] = "complete"
        fmeta["features"] = {k: {"shape": list(a.shape), "dtype": a.dtype.str} for k, a in feats.items()}
        rio.atomic_write_json(fside, fmeta)
        return {"n": n, "chunks": n_chunks, "new_chunks": n_chunks - len(done), "features": {k: list(a.shape) for k, a in feats.items()}}


def _remove_features(path: Path) -> None:
    """Delete old features: sidecar first, so a kill leaves only ignorable orphan chunks."""
    with contextlib.suppress(FileNotFoundError):
        (path / FEATURES_SIDECAR).unlink()
    fdir = path / FEATURES
    if fdir.exists():
        tmp = path / f".{FEATURES}.old.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        os.replace(fdir, tmp)
        shutil.rmtree(tmp)


# ----------------------------------------------------------------------------- info


def _rates(label: np.ndarray, groups: np.ndarray, keys: Sequence[str]) -> tuple[dict, dict]:
    rate, count = {}, {}
    for key in keys:
        m = groups == key
        k, p = int(m.sum()), int(label[m].sum())
        rate[key] = p / k if k else None
        count[key] = {"n": k, "positives": p}
    return rate, count


def _group_stats(prefix: str, d: Mapping[str, np.ndarray]) -> dict[str, Any]:
    label = d["label"]
    n = len(label)
    pair = np.char.add(np.char.add(d["toy"].astype(str), "/"), d["other"].astype(str)) if n else np.zeros(0, str)
    rel_rate, rel_count = _rates(label, d["relation"], RELATIONS)
    pair_rate, pair_count = _rates(label, pair, sorted(set(pair.tolist())))
    return {
        f"{prefix}positive_rate": float(label.mean()) if n else None,
        f"{prefix}positive_rate_by_relation": rel_rate,
        f"{prefix}count_by_relation": rel_count,
        f"{prefix}positive_rate_by_pair": pair_rate,
        f"{prefix}count_by_pair": pair_count,
    }


def info(path: str | os.PathLike) -> dict[str, Any]:
    """Counts and positive rates of a dataset (JSON-serialisable).

    Keys: ``action``, ``status``, ``n`` (selected samples), ``n_positive``, ``n_negative``,
    ``positive_rate``, ``positive_rate_by_relation`` {relation: rate or None},
    ``count_by_relation`` {relation: {n, positives}}, ``positive_rate_by_pair`` and
    ``count_by_pair`` keyed ``"toy/other"`` -- all over the selected samples; the same with a
    ``rollouts_`` prefix over every rollout; ``rollouts``, ``chunks``, ``batch``, ``seed``,
    ``borrowed`` (negatives taken outside their distance bin), ``config``, ``versions``; and
    ``features``: None, or {status, chunks, arrays {name: {shape, dtype}}, unseen_samples
    (samples with any unseen flag set), unseen_by_column}.
    """
    path = Path(path)
    meta = _read_sidecar(path)
    rollouts = load_rollouts(path)
    out: dict[str, Any] = {
        "path": str(path),
        "action": meta["action"],
        "status": meta["status"],
        "seed": meta["seed"],
        "batch": meta["batch"],
        "requested_n": meta["n_samples"],
        "rollouts": len(rollouts["label"]),
        "chunks": meta["counts"]["chunks"],
    }
    sel = rollouts["selected"]
    chosen = {k: v[sel] for k, v in rollouts.items() if isinstance(v, np.ndarray)}
    out["n"] = int(sel.sum())
    out["n_positive"] = int(chosen["label"].sum())
    out["n_negative"] = out["n"] - out["n_positive"]
    out.update(_group_stats("", chosen))
    out.update(_group_stats("rollouts_", rollouts))
    out["borrowed"] = meta.get("selection", {}).get("borrowed")
    out["features"] = None
    fmeta = _read_features_sidecar(path)
    if fmeta is not None:
        feat: dict[str, Any] = {"status": fmeta["status"], "chunks": fmeta["chunks"]}
        if fmeta["status"] == "complete" and meta["status"] == "complete":
            data = load_dataset(path)
            names = [k for k in data if k not in chosen and k != "action"]
            feat["arrays"] = {k: {"shape": list(data[k].shape), "dtype": data[k].dtype.name} for k in names}
            if "unseen" in data:
                u = data["unseen"].reshape(len(data["unseen"]), -1)
                feat["unseen_samples"] = int(u.any(axis=1).sum())
                feat["unseen_by_column"] = u.sum(axis=0).astype(int).tolist()
        out["features"] = feat
    out["config"] = meta.get("config")
    out["versions"] = meta.get("versions")
    return out


def _fmt_rate(rate: float | None) -> str:
    return "-" if rate is None else f"{rate:6.1%}"


def format_info(d: Mapping[str, Any]) -> str:
    """Human-readable table of an ``info`` dict."""
    lines = [f"dataset {d['path']}: action {d['action']}, {d['status']}"]
    if d["status"] == "complete":
        lines.append(
            f"samples: {d['n']} ({d['n_positive']} positive, {_fmt_rate(d['positive_rate']).strip()}) "
            f"from {d['rollouts']} rollouts in {d['chunks']} chunks; "
            f"{d['borrowed']} negatives borrowed across distance bins"
        )
    else:
        lines.append(f"generating: {d['rollouts']} rollouts in {d['chunks']} chunks, target {d['requested_n']} samples")
    lines.append(f"rollouts positive rate: {_fmt_rate(d['rollouts_positive_rate']).strip()}")
    lines.append("")
    lines.append(f"{'relation':<10} {'samples':>8} {'pos rate':>8} {'rollouts':>9} {'pos rate':>8}")
    for r in RELATIONS:
        c, rc = d["count_by_relation"][r], d["rollouts_count_by_relation"][r]
        lines.append(
            f"{r:<10} {c['n']:>8} {_fmt_rate(d['positive_rate_by_relation'][r]):>8} "
            f"{rc['n']:>9} {_fmt_rate(d['rollouts_positive_rate_by_relation'][r]):>8}"
        )
    lines.append("")
    pairs = sorted(d["rollouts_count_by_pair"])
    width = max([len("pair")] + [len(p) for p in pairs])
    lines.append(f"{'pair':<{width}} {'samples':>8} {'pos rate':>8} {'rollouts':>9} {'pos rate':>8}")
    for p in pairs:
        c = d["count_by_pair"].get(p, {"n": 0})
        lines.append(
            f"{p:<{width}} {c['n']:>8} {_fmt_rate(d['positive_rate_by_pair'].get(p)):>8} "
            f"{d['rollouts_count_by_pair'][p]['n']:>9} {_fmt_rate(d['rollouts_positive_rate_by_pair'][p]):>8}"
        )
    f = d.get("features")
    lines.append("")
    if f is None:
        lines.append("features: none")
    else:
        lines.append(f"features: {f['status']} ({f['chunks']} chunks)")
        for k, s in f.get("arrays", {}).items():
            lines.append(f"  {k:<10} {tuple(s['shape'])} {s['dtype']}")
        if "unseen_samples" in f:
            lines.append(f"  unseen flag set on {f['unseen_samples']} samples (by column {f['unseen_by_column']})")
    return "\n".join(lines)


def _cli_info(args) -> int:
    d = info(args.dir)
    if args.json:
        print(json.dumps(d, sort_keys=True))
    else:
        print(format_info(d))
    return 0


def register_cli(subparsers) -> None:
    """Add ``relaff info DIR [--json]``."""
    p = subparsers.add_parser(
        "info",
        help="counts and positive rates of a dataset",
        description="Show counts, positive rates by spatial relation and by object pair, "
        "rollouts used and attached features of a relaff dataset.",
    )
    p.add_argument("dir", metavar="DIR", help="dataset directory")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=_cli_info)
