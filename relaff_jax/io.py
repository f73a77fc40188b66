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
import errno
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from relaff_jax.diskspace import NO_SPACE, disk_full, is_no_space  # noqa: F401  (re-exported: rio.disk_full, rio.is_no_space)
from relaff_jax.errors import CorruptFileError, UserError


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


_FENCE: list = []  # [callable]: whether this process may still write (set in worker processes)


def set_write_fence(allowed) -> None:
    """In a worker process: ``allowed()`` is asked before every atomic rename; False (its
    driver, which holds the folder's lock, is gone) discards the write and ends the process."""
    _FENCE[:] = [allowed]


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temp file in the same dir + rename). A full
    disk is a ``DiskFullError`` naming the folder and the size of the write; the old file,
    if any, is untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        _chmod_default(tmp, directory=False)
        if _FENCE and not _FENCE[0]():  # a worker whose driver is gone: its lock went with it
            os.unlink(tmp)
            os._exit(0)
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException as e:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(e, OSError) and e.errno in NO_SPACE:
            raise disk_full(e, path.parent, len(data)) from e
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
    """Read JSON, turning a corrupt file (bad JSON, not UTF-8) into a ``CorruptFileError``
    (a ``UserError``, so a ``ValueError``) that names it."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise CorruptFileError(f"{path}: corrupt JSON ({e})") from e
    except UnicodeDecodeError as e:
        raise CorruptFileError(f"{path}: not a UTF-8 JSON file (byte {e.start}: {e.reason})") from e
    except IsADirectoryError as e:
        raise CorruptFileError(f"{path}: a folder where a JSON file is expected") from e


def load_npz(path: str | os.PathLike, keys: Any = None) -> dict[str, np.ndarray]:
    """Every array (or those in ``keys``) of the ``.npz`` file ``path``, read at once; a
    truncated or foreign file is a ``CorruptFileError`` naming it (``np.load`` raises one of
    half a dozen types, depending on where the damage lies)."""
    import zipfile
    import zlib

    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            names = z.files if keys is None else [k for k in keys if k in z.files]
            return {k: z[k] for k in names}
    except (FileNotFoundError, PermissionError):
        raise
    except (zipfile.BadZipFile, zlib.error, EOFError, ValueError, KeyError, AttributeError, TypeError, OSError) as e:
        raise CorruptFileError(f"{path}: truncated or not a numpy .npz file ({type(e).__name__}: {e}); "
                               "delete it and rerun the command that wrote it") from e


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

    lock = Path(path) / name
    try:  # never through a link: a planted .relaff.lock symlink must not create or lock its target
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
    except OSError as e:
        if e.errno == errno.ELOOP or lock.is_symlink():
            raise UserError(f"{lock} is a symbolic link; relaff locks only a plain file there: remove the link "
                            "and rerun") from None
        raise
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UserError(busy) from None
        _HELD.append(str(lock))
        try:
            yield
        finally:
            _HELD.remove(str(lock))
    finally:
        os.close(fd)


_HELD: list[str] = []  # the lock files this process holds (``folder_lock``), for its workers' fence


def held_locks() -> list[str]:
    """The folder locks this process holds now: a worker's writes are fenced on them."""
    return list(_HELD)


def lock_is_held(path: str | os.PathLike) -> bool | None:
    """Whether some process holds a ``flock`` on the file ``path`` (Linux's ``/proc/locks``),
    read without taking it; None where that cannot be told. A lock goes when its holder's
    files close, before its children are handed to init: the exact moment a worker must stop
    writing."""
    try:
        st = os.lstat(path)
        key = f" {os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino} "
        with open("/proc/locks", encoding="ascii", errors="replace") as f:
            return any(key in line and "FLOCK" in line and "->" not in line for line in f)
    except OSError:
        return None


def remove_tree(path: str | os.PathLike) -> None:
    """Delete a folder so that a kill leaves no half-deleted output under its name: it is
    renamed to a hidden ``.NAME.old.tmp`` first (``clean_leftovers`` removes those)."""
    path = Path(path)
    if path.is_symlink():
        raise UserError(f"{path} is a symbolic link (to {os.readlink(path)}); relaff does not delete through "
                        "links: replace the link by a folder (or remove it) and rerun")
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


def _exists(path: Path) -> bool:
    """``path.exists()``, False where the name itself is unusable (too long)."""
    try:
        return path.exists()
    except OSError:
        return False


def check_path_length(path: str | os.PathLike, what: str = "--out") -> None:
    """Fail at once (``UserError``) if ``path`` or one of its parts is longer than its file
    system allows (NAME_MAX, usually 255 bytes; PATH_MAX, usually 4096), leaving room for
    the hidden temporary siblings the atomic writes make (``.NAME.xxxxxxxx.tmp``)."""
    path = Path(path)
    probe = path.absolute()
    while not _exists(probe) and probe.parent != probe:
        probe = probe.parent
    try:
        name_max, path_max = os.pathconf(probe, "PC_NAME_MAX"), os.pathconf(probe, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    room = 24  # ".NAME." + mkstemp's 8 characters + ".old.tmp"
    text = str(path)
    shown = text if len(text) <= 100 else f"{text[:40]}...{text[-40:]}"
    for part in path.parts:
        n = len(os.fsencode(part))
        if n + room > name_max:
            raise UserError(f"{what} {shown}: the name {part[:20]}...{part[-10:]} is {n} bytes long; this file "
                            f"system allows {name_max} (and relaff needs {room} more for its temporary files)")
    if len(os.fsencode(str(path.absolute()))) + room > path_max:
        raise UserError(f"{what} {shown}: the path is {len(os.fsencode(str(path.absolute())))} bytes long; this "
                        f"system allows {path_max}")


def check_writable_dir(path: str | os.PathLike, what: str = "--out") -> None:
    """Fail at once (``UserError``) if ``path`` cannot be an output folder: it is a file, lies
    under a file, or its nearest existing ancestor cannot be written. Called before any
    simulation or learning, so a typo costs no minutes."""
    path = Path(path)
    check_path_length(path, what)
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
    path = Path(path)
    check_path_length(path, what)
    if path.is_dir():
        raise UserError(f"{what} {path} is a folder; give a file name")
    check_writable_dir(path.parent, what=f"{what} {path}: folder")
