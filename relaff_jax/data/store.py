"""Chunk storage of a dataset directory: orbax chunks, the sidecar, the writer lock, the folder.

Takes paths and arrays; gives atomic chunk writes (``write_chunk``: an orbax PyTree checkpoint
``arrays/`` plus ``meta.json`` with each array's dtype, shape and sha256 and the vocabulary of
string fields), verified chunk reads (``read_chunk``, ``CorruptDatasetError`` on any damage),
the dataset sidecar (``read_sidecar``), the exclusive writer lock (``writer_lock``), and the
creation and clean-up of a dataset folder (``prepare_dir``, ``remove_created``, ``clean_tmp``).

Reads go through tensorstore's synchronous API when the chunk has orbax's OCDBT layout (what
this package writes): orbax's restore runs tensorstore futures in a private asyncio loop that
it closes on the first failed read, and the still-pending reads then print "RuntimeError:
Event loop is closed" tracebacks when they are collected, after our clear error message.
Every array is checked against the sha256 written beside it, so either path returns exactly
the stored bytes; a layout this reader does not recognise goes to orbax's restore.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import re
import shutil
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.data.layout import CHUNKS, FORMAT, FORMAT_VERSION, LOCK, SELECTION, SIDECAR
from relaff_jax.data.errors import CorruptDatasetError, DatasetError, ForeignDirectoryError

CHUNK_RE = re.compile(r"^chunk_(\d{6})$")

_CHECKPOINTER = None


def _checkpointer():
    # One synchronous PyTree checkpointer: ~40 ms per save, ~10 ms per restore of a chunk.
    global _CHECKPOINTER
    if _CHECKPOINTER is None:
        import orbax.checkpoint as ocp

        _CHECKPOINTER = ocp.PyTreeCheckpointer()
    return _CHECKPOINTER


def sha256(a: np.ndarray) -> str:
    """Hex sha256 of an array's bytes (C order)."""
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


class _NoSpaceFilter(logging.Filter):
    """Drops orbax's own log of a full disk (an ERROR with its thread's traceback): the write
    re-raises it and the CLI reports it as one line; every other record passes."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return not ((exc is not None and rio.is_no_space(exc)) or "No space left on device" in record.getMessage())


def _quiet_full_disk_logs() -> None:
    log = logging.getLogger("absl")
    if not any(isinstance(f, _NoSpaceFilter) for f in log.filters):
        log.addFilter(_NoSpaceFilter())


def write_chunk(path: Path, arrays: Mapping[str, np.ndarray], extra: Mapping[str, Any]) -> None:
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
    meta["arrays"] = {k: {"dtype": a.dtype.str, "shape": list(a.shape), "sha256": sha256(a)} for k, a in tree.items()}
    meta["vocab"] = vocab
    _quiet_full_disk_logs()
    with rio.atomic_directory(path) as tmp:
        try:
            _checkpointer().save(str((tmp / "arrays").resolve()), tree)
        except Exception as e:  # tensorstore's full disk is a ValueError: one line naming the folder
            if rio.is_no_space(e):
                raise rio.disk_full(e, path.parent, sum(a.nbytes for a in tree.values())) from None
            raise
        rio.atomic_write_json(tmp / "meta.json", meta)
        # Only a chunk that reads back lands: a killed driver's task still writing on a worker
        # can have its temporary folder removed under it by the restarted driver's clean_tmp
        # (orbax then finishes an incomplete checkpoint); it must fail, not rename that.
        read_chunk(tmp)


def read_chunk(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read and verify one chunk; strings decoded. Raises CorruptDatasetError."""
    try:
        meta = rio.read_json(path / "meta.json")
    except (OSError, ValueError) as e:
        raise CorruptDatasetError(f"chunk {path}: metadata missing or corrupt ({e})") from e
    if not (path / "arrays").is_dir():
        raise CorruptDatasetError(f"chunk {path}: orbax cannot read it (its arrays/ checkpoint is missing)")
    spec = meta.get("arrays", {})
    try:
        tree = _read_tree(path / "arrays", spec)
    except Exception as e:  # orbax/tensorstore raise many types on damaged files
        raise CorruptDatasetError(f"chunk {path}: orbax cannot read it ({type(e).__name__}: {e})") from e
    if not isinstance(tree, dict) or set(tree) != set(spec):
        raise CorruptDatasetError(f"chunk {path}: stored arrays do not match its metadata")
    out: dict[str, np.ndarray] = {}
    for k, s in spec.items():
        a = np.asarray(tree[k])
        if a.dtype.str != s["dtype"] or list(a.shape) != s["shape"] or sha256(a) != s["sha256"]:
            raise CorruptDatasetError(f"chunk {path}: array {k!r} is corrupt (checksum/shape mismatch)")
        if k in meta.get("vocab", {}):
            names = np.asarray(meta["vocab"][k], dtype=str)
            if a.size and (a.min() < 0 or a.max() >= len(names)):
                raise CorruptDatasetError(f"chunk {path}: codes of {k!r} outside its vocabulary")
            a = names[a]
        out[k] = a
    return out, meta


def _read_tree(arrays_dir: Path, spec: Mapping[str, Any]) -> Any:
    """The stored arrays of one chunk: synchronous tensorstore reads of orbax's OCDBT/zarr
    layout (no asyncio, see the module docstring), or orbax's restore for another layout."""
    root = arrays_dir.resolve()
    try:
        keys = set(json.loads((root / "_METADATA").read_text())["tree_metadata"])
    except (OSError, ValueError, KeyError, TypeError):
        keys = None
    if keys != {f"('{k}',)" for k in spec} or not (root / "manifest.ocdbt").is_file():
        return _checkpointer().restore(str(root))
    import tensorstore as ts

    kvstore = {"driver": "ocdbt", "base": f"file://{root}/"}
    out = {}
    for k in spec:
        store = ts.open({"driver": "zarr", "kvstore": dict(kvstore, path=f"{k}/")}, open=True, read=True)
        out[k] = np.asarray(store.result().read().result())
    return out


def chunk_indices(cdir: Path) -> list[int]:
    """Sorted indices of finished chunks in ``cdir``; a gap is a truncated dataset."""
    if not cdir.is_dir():
        return []
    found = sorted(int(m.group(1)) for p in cdir.iterdir() if (m := CHUNK_RE.match(p.name)) and p.is_dir())
    if found != list(range(len(found))):
        missing = sorted(set(range(found[-1] + 1)) - set(found))
        raise CorruptDatasetError(f"{cdir}: chunk(s) {missing} missing before later chunks (truncated)")
    return found


def chunk_path(cdir: Path, k: int) -> Path:
    return cdir / f"chunk_{k:06d}"


def clean_tmp(*dirs: Path) -> list[str]:
    """Remove leftovers of killed atomic writes (``.NAME.XXXX.tmp`` files/dirs). Tolerates a
    writer still at work in one (a killed driver's task on a cluster worker): what it adds or
    removes meanwhile is no error here; its own rename then fails and the chunk is redone."""
    removed = []
    for d in dirs:
        if not d.is_dir():
            continue
        for p in d.iterdir():
            if p.name.startswith(".") and p.name.endswith(".tmp"):
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
                removed.append(str(p))
    return removed


def concat(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    if not parts:
        return {}
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def read_sidecar(path: Path) -> dict[str, Any]:
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
    _check_types(path, meta)
    meta.setdefault("engine", "mjx")  # sidecars from before the native engine existed are MJX's
    meta["config"] = config_record(meta.get("config"), meta["action"])
    return meta


_SIDECAR_TYPES = {"action": str, "status": str, "n_samples": int, "seed": int, "batch": int, "counts": dict,
                  "selection": dict, "selection_scheme": dict, "engine": str}
_COUNT_KEYS = ("chunks", "positives", "negatives", "in_hand", "rollouts")


def _check_types(path: Path, meta: dict) -> None:
    """Each field the readers use has its JSON type (a sidecar edited by hand, or by another
    program, is refused by name rather than failing deep inside ``info`` or ``load``)."""
    def bad(key, want, got):
        return CorruptDatasetError(f"{path}: sidecar {SIDECAR}: {key} should be {want}, got {got!r:.60}")

    for key, t in _SIDECAR_TYPES.items():
        v = meta.get(key)
        if key in meta and (not isinstance(v, t) or (t is int and isinstance(v, bool))):
            raise bad(key, "an integer" if t is int else f"a JSON {'object' if t is dict else 'string'}", v)
    for key in _COUNT_KEYS:
        v = meta["counts"].get(key)
        if key in meta["counts"] and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
            raise bad(f"counts.{key}", "an integer >= 0", v)
    if "chunks" not in meta["counts"]:
        raise CorruptDatasetError(f"{path}: sidecar {SIDECAR} lacks counts.chunks")


def config_record(record: Any, action: str) -> Any:
    """The sidecar's ``config`` in its one shape, ``{"action": NAME, "action_config": {...}}``
    (what ``relaff generate`` and ``reproduce`` both write); ``relaff generate`` wrote
    ``{"action": {...}}`` before, read here as the same record so such datasets resume."""
    if isinstance(record, dict) and isinstance(record.get("action"), dict) and "action_config" not in record:
        return {**record, "action": action, "action_config": record["action"]}
    return record


@contextlib.contextmanager
def writer_lock(path: Path) -> Iterator[None]:
    """Exclusive advisory lock so two writers never interleave chunks in one directory.

    Non-blocking: a second writer gets a ``DatasetError`` at once. The lock file stays (it is
    ignored by readers and by ``prepare_dir``) unless ``remove_created`` takes the folder away.
    """
    import fcntl

    try:  # never through a link: a planted lock symlink must not create or lock its target
        fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
    except OSError as e:
        if (path / LOCK).is_symlink():
            raise DatasetError(f"{path / LOCK} is a symbolic link; relaff locks only a plain file there: remove "
                               "the link and rerun") from None
        raise DatasetError(f"{path}: directory is not writable ({e})") from e
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetError(f"{path}: another process is writing this dataset") from None
        # The lock file may have been removed (with the folder it made) by the writer that held
        # it before us: a lock on the unlinked file would exclude nobody.
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path / LOCK))
        except OSError:
            same = False
        if not same:
            raise DatasetError(f"{path}: another process removed this dataset folder while we waited; rerun")
        yield
    finally:
        os.close(fd)


def prepare_dir(path: Path) -> bool:
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


def mismatch(stored: Mapping[str, Any], wanted: Mapping[str, Any], keys: Sequence[str]) -> list[str]:
    """One ``"key: stored X, requested Y"`` line per key whose values differ."""
    def short(v: Any) -> str:
        s = json.dumps(v, sort_keys=True)
        return s if len(s) <= 80 else s[:77] + "..."

    return [f"{k}: stored {short(stored.get(k))}, requested {short(wanted.get(k))}" for k in keys if stored.get(k) != wanted.get(k)]


def remove_created(path: Path) -> None:
    """Undo ``prepare_dir``'s creation of ``path`` after a failure before the first chunk.

    Call only while holding ``writer_lock(path)`` and only if this process created the folder:
    removes what a writer puts there before the first chunk (sidecar, empty ``chunks/``,
    leftovers of killed atomic writes, the lock file) and then the folder if it is empty, so
    anything another process put there stays.
    """
    clean_tmp(path / CHUNKS, path)
    with contextlib.suppress(FileNotFoundError):
        (path / SIDECAR).unlink()
    with contextlib.suppress(OSError):
        (path / CHUNKS).rmdir()
    with contextlib.suppress(FileNotFoundError):
        (path / LOCK).unlink()
    with contextlib.suppress(OSError):
        path.rmdir()


def chunk_dirs_exist(path: Path) -> bool:
    """True once ``path/chunks`` holds a finished or in-progress chunk folder."""
    cdir = path / CHUNKS
    return cdir.is_dir() and any(CHUNK_RE.match(p.name) for p in cdir.iterdir())


def check_rollout_ids(where: Path, arrays: Mapping[str, np.ndarray], k: int, batch: int) -> None:
    ids = arrays.get("rollout")
    if ids is None or not np.array_equal(ids, k * batch + np.arange(batch)):
        raise CorruptDatasetError(f"chunk {where}: rollout ids are not those of chunk {k} (renamed or mixed chunk)")
