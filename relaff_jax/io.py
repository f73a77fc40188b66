"""Atomic file and directory writes shared by every stage.

A run that is killed must never leave a half-written file where a finished one is
expected: everything is written to a temporary sibling and renamed into place
(``os.replace`` is atomic on POSIX within one file system).

Permissions follow the umask, as ``open`` and ``mkdir`` would give them: ``tempfile`` creates
files 0600 and folders 0700 whatever the umask, which would hide reports and datasets from a
colleague, a notebook server or a web server running as another user.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np


def _umask() -> int:
    """The process umask, read without changing it where Linux allows (``os.umask`` can only
    set it: setting and restoring would open a window in which another thread's new file
    gets umask 0)."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0)  # elsewhere: set and restore at once
    os.umask(mask)
    return mask


def _chmod_default(path: str | os.PathLike, directory: bool) -> None:
    """Give ``path`` the mode a plain ``open``/``mkdir`` would (0666/0777 minus the umask)."""
    os.chmod(path, (0o777 if directory else 0o666) & ~_umask())


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temp file in the same dir + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        _chmod_default(tmp, directory=False)
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def jsonable(obj: Any) -> Any:
    """``obj`` as it reads back from JSON (tuples become lists, numpy scalars numbers): the
    form in which stored and requested configs are compared."""
    return json.loads(json.dumps(obj, sort_keys=True, default=json_default))


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=json_default) + "\n")


def read_json(path: str | os.PathLike) -> Any:
    """Read JSON, turning a corrupt file into a ValueError that names it."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: corrupt JSON ({e})") from e


def atomic_save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """``np.savez`` to ``path`` atomically (used for small per-block results)."""
    import io as _io

    buf = _io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary directory that is renamed to ``path`` only on success.

    ``path`` must not exist yet; on any exception the temporary directory is removed,
    so a killed or failed writer leaves nothing behind under the final name.
    """
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path} already exists")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    _chmod_default(tmp, directory=True)
    try:
        yield tmp
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


@contextlib.contextmanager
def folder_lock(path: str | os.PathLike, busy: str, name: str = ".relaff.lock") -> Iterator[None]:
    """Hold an exclusive advisory lock on folder ``path`` (its file ``name``) while the body runs,
    so that a second writer is refused at once (``UserError(busy)``) rather than interleaved.
    The lock file stays (readers ignore it); the lock goes with the process, even on kill -9."""
    import fcntl

    from relaff_jax.errors import UserError

    fd = os.open(Path(path) / name, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UserError(busy) from None
        yield
    finally:
        os.close(fd)


def remove_tree(path: str | os.PathLike) -> None:
    """Delete a folder so that a kill leaves no half-deleted output under its name: it is
    renamed to a hidden ``.NAME.old.tmp`` first (``clean_leftovers`` removes those)."""
    path = Path(path)
    if not path.exists():
        return
    tmp = path.parent / f".{path.name}.old.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    os.replace(path, tmp)
    shutil.rmtree(tmp)


def clean_leftovers(root: str | os.PathLike) -> None:
    """Remove the hidden leftovers of ``remove_tree`` calls that were killed."""
    for p in Path(root).glob(".*.old.tmp"):
        shutil.rmtree(p, ignore_errors=True)


def check_writable_dir(path: str | os.PathLike, what: str = "--out") -> None:
    """Fail at once (``UserError``) if ``path`` cannot be an output folder: it is a file, lies
    under a file, or its nearest existing ancestor cannot be written. Called before any
    simulation or learning, so a typo costs no minutes."""
    from relaff_jax.errors import UserError

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{what} {path} exists and is a file, not a folder")
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise UserError(f"{what} {path}: {probe} is a file, so no folder can be made under it")
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as e:
        raise UserError(f"{what} {path}: cannot write in {probe} ({e.strerror or e})") from e


def check_writable_file(path: str | os.PathLike, what: str = "--out") -> None:
    """Fail at once (``UserError``) if ``path`` cannot be an output file: it is a folder, or
    its folder cannot be made or written (``check_writable_dir``)."""
    from relaff_jax.errors import UserError

    path = Path(path)
    if path.is_dir():
        raise UserError(f"{what} {path} is a folder; give a file name")
    check_writable_dir(path.parent, what=f"{what} {path}: folder")
