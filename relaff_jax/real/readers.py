"""One entry point for every real-cloud format: ``read_cloud(path) -> RealCloud``.

Takes a path ending in ``.pcd`` (``pcd.read_pcd``), ``.ply`` (``ply.read_ply``) or ``.npz``
(``read_npz``: arrays ``xyz`` (H, W, 3) or (N, 3), optional ``rgb``, ``label``, ``intrinsics``
(4,) = fx, fy, cx, cy; any other array goes to ``fields``); gives a ``RealCloud``.
``write_npz`` writes that layout atomically.
"""
from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.io import atomic_save_npz

from .cloud import RealCloud, make_cloud
from .pcd import read_pcd
from .ply import read_ply

FORMATS = (".pcd", ".ply", ".npz")


def read_npz(path) -> RealCloud:
    """Read an ``.npz`` with ``xyz`` [+ ``rgb``, ``label``, ``intrinsics``] into a ``RealCloud``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise UserError(f"cannot read {path} as .npz: {e}") from None
    if "xyz" not in arrays:
        raise UserError(f"{path}: .npz has no 'xyz' array (has: {', '.join(sorted(arrays)) or 'nothing'})")
    xyz = arrays.pop("xyz")
    return make_cloud(xyz, rgb=arrays.pop("rgb", None), label=arrays.pop("label", None),
                      intrinsics=arrays.pop("intrinsics", None), fields=arrays, path=os.fspath(path))


def write_npz(path, cloud: RealCloud) -> None:
    """Write ``cloud`` as ``.npz`` (xyz, rgb, label, intrinsics when present, fields), atomically."""
    arrays = dict(cloud.fields)
    arrays["xyz"] = cloud.xyz
    for name in ("rgb", "label"):
        if getattr(cloud, name) is not None:
            arrays[name] = getattr(cloud, name)
    if cloud.intrinsics is not None and cloud.intrinsics_source == "file":
        arrays["intrinsics"] = np.asarray(cloud.intrinsics, np.float64)
    atomic_save_npz(path, **arrays)


def read_cloud(path) -> RealCloud:
    """Read a real point cloud by its file extension (.pcd, .ply, .npz); UserError otherwise."""
    ext = Path(path).suffix.lower()
    if not Path(path).is_file():
        raise UserError(f"no such point-cloud file: {path}")
    if ext == ".pcd":
        return read_pcd(path)
    if ext == ".ply":
        return read_ply(path)
    if ext == ".npz":
        return read_npz(path)
    raise UserError(f"{path}: unknown point-cloud format {ext!r}; valid: {', '.join(FORMATS)}")
