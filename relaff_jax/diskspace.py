"""A full disk as one line: what a failed write (ENOSPC, EDQUOT, or a library's wrapping of
them) says, naming the folder, the space left and the size of the write. ``relaff_jax.io``
re-exports these; the CLI's top level and the atomic writers use them."""
from __future__ import annotations

import errno
import os
from pathlib import Path
from relaff_jax.errors import DiskFullError

NO_SPACE = (errno.ENOSPC, errno.EDQUOT)


def free_bytes(folder: str | os.PathLike) -> int | None:
    """Bytes free to this user in the file system of ``folder`` (its nearest existing
    ancestor), or None if it cannot be told."""
    probe = Path(folder)
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    try:
        st = os.statvfs(probe)
    except OSError:
        return None
    return st.f_bavail * st.f_frsize


def _mb(n: float) -> str:
    return f"{n / 1e6:.1f} MB"


def disk_full(e: OSError, folder: str | os.PathLike, needed: int | None = None) -> "DiskFullError":
    """The one-line error of a write that found no space in ``folder``'s file system."""
    free = free_bytes(folder)
    need = f"; this write needed {_mb(needed)}" if needed else ""
    have = f" ({_mb(free)} free)" if free is not None else ""
    return DiskFullError(f"no space left in {folder}{have}{need}: free some space (or give a folder on another "
                         "disk) and rerun the same command; what was finished is kept")


def is_no_space(e: BaseException) -> bool:
    """Whether ``e`` (or what caused it) is a full disk: an ``OSError`` ENOSPC/EDQUOT, or the
    text of one wrapped by another library (tensorstore, under orbax, raises ``ValueError``
    "RESOURCE_EXHAUSTED ... No space left on device [os_error_code='28']")."""
    seen = set()
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if isinstance(e, OSError) and e.errno in NO_SPACE:
            return True
        text = str(e)
        if "No space left on device" in text or "Disk quota exceeded" in text or "os_error_code='28'" in text:
            return True
        e = e.__cause__ or e.__context__
    return False
