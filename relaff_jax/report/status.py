"""Is a report folder whole, and was it made from these inputs?

A finished report carries ``report_stamp.json``: a hash of the files it was made from and the
settings that shape it. ``report_status`` compares it with the stamp the inputs give now;
``inputs_stamp`` computes that stamp. The writer removes the stamp before rewriting a
report and writes it last, so a killed writer leaves a report without a stamp (partial).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from relaff_jax import io as rio

from relaff_jax.report.folder import REQUIRED, STAMP  # noqa: F401 (re-exported)


def hash_files(files: Sequence[Path]) -> str:
    """sha256 over the names and bytes of ``files`` (a missing file hashes as ``<missing>``)."""
    h = hashlib.sha256()
    for f in files:
        h.update(str(Path(f).name).encode())
        h.update(Path(f).read_bytes() if Path(f).exists() else b"<missing>")
    return h.hexdigest()


def inputs_stamp(inputs: Sequence[Path], settings: Mapping[str, Any]) -> dict[str, Any]:
    """The stamp of a report made from ``inputs`` (files) with ``settings``."""
    return {"inputs": hash_files(inputs), **dict(settings)}


def report_status(out: str | os.PathLike, stamp: Mapping[str, Any]) -> tuple[str, str]:
    """``(state, why)`` of the report folder ``out`` for the inputs behind ``stamp``."""
    out = Path(out)
    if not out.exists():
        return "absent", "no folder"
    missing = [f for f in REQUIRED if not (out / f).exists()]
    if not (out / STAMP).exists() or missing:
        return "partial", f"unfinished ({', '.join(missing) or 'no stamp'})"
    try:
        stored = rio.read_json(out / STAMP)
    except ValueError as e:
        return "corrupt", str(e)
    if stored != rio.jsonable(dict(stamp)):
        return "stale", "made from other results, datasets or settings"
    return "complete", "stamped with the current inputs"


def clear_stamp(out: str | os.PathLike) -> None:
    """Remove the stamp before a report is rewritten: no stamp until it is whole again."""
    p = Path(out) / STAMP
    if p.exists():
        p.unlink()


def write_stamp(out: str | os.PathLike, stamp: Mapping[str, Any]) -> None:
    rio.atomic_write_json(Path(out) / STAMP, dict(stamp))
