"""PLY point clouds: ``read_ply`` and ``write_ply``.

Takes a ``.ply`` path (``format ascii 1.0`` or ``binary_little_endian 1.0``) whose ``vertex``
element has float/int properties x, y, z and optionally red, green, blue (uchar, or floats in
[0, 1]); gives an unorganized ``RealCloud`` (xyz (N, 3) float32, rgb (N, 3) uint8 or None, the
other scalar vertex properties in ``fields``). Elements before ``vertex`` are skipped (in
binary files only if they have no list properties); elements after it are ignored.
"""
from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.io import atomic_write_bytes

from .cloud import RealCloud, make_cloud

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
              "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4",
              "uint32": "<u4", "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8"}


def _parse_header(raw: bytes, path):
    """(format, elements [(name, count, [(prop, dtype) or (prop, None) for a list])], data offset)."""
    if not raw.startswith(b"ply"):
        raise UserError(f"{path}: not a PLY file (no 'ply' magic line)")
    end = raw.find(b"end_header")
    if end < 0:
        raise UserError(f"{path}: truncated PLY header (no end_header)")
    off = raw.find(b"\n", end) + 1
    fmt, elements = None, []
    for line in raw[:end].decode("ascii", "replace").splitlines()[1:]:
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] in ("format", "property") and len(tok) < (2 if tok[0] == "format" else 3):
            raise UserError(f"{path}: PLY header line {line.strip()!r} is incomplete")
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            if len(tok) != 3 or not tok[2].isdigit():
                raise UserError(f"{path}: PLY element line {' '.join(tok)!r} is not 'element NAME COUNT'")
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property":
            if not elements:
                raise UserError(f"{path}: PLY property before any element")
            if tok[1] == "list":
                if len(tok) != 5:
                    raise UserError(f"{path}: PLY list property {line.strip()!r} is not 'property list COUNT_TYPE "
                                    "ITEM_TYPE NAME'")
                elements[-1][2].append((tok[-1], None))
            else:
                dt = _PLY_TYPES.get(tok[1])
                if dt is None:
                    raise UserError(f"{path}: unknown PLY property type {tok[1]!r}")
                elements[-1][2].append((tok[2], np.dtype(dt)))
    if fmt not in ("ascii", "binary_little_endian"):
        raise UserError(f"{path}: unsupported PLY format {fmt!r}; valid: ascii, binary_little_endian")
    return fmt, elements, off


def read_ply(path) -> RealCloud:
    """Read the vertices of a PLY file into an unorganized ``RealCloud``; UserError for a
    truncated file, an unsupported format or a vertex element without x, y, z."""
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise UserError(f"cannot read {path}: {e.strerror}") from None
    fmt, elements, off = _parse_header(raw, path)
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise UserError(f"{path}: PLY has no vertex element")
    vi = names.index("vertex")
    _, n, props = elements[vi]
    if any(dt is None for _, dt in props):
        raise UserError(f"{path}: list properties in the vertex element are not supported")
    if any(p not in [q for q, _ in props] for p in "xyz"):
        raise UserError(f"{path}: the vertex element has no x, y and z properties")
    if fmt == "ascii":
        lines = raw[off:].decode("ascii", "replace").splitlines()
        skip = sum(e[1] for e in elements[:vi])
        rows = lines[skip:skip + n]
        if len(rows) < n:
            raise UserError(f"{path}: truncated ascii PLY: {len(rows)} of {n} vertices")
        try:
            vals = np.array(" ".join(rows).split()).astype(np.float64).reshape(n, len(props))
        except ValueError:
            raise UserError(f"{path}: a PLY vertex line has too few or non-numeric values") from None
        cols = {p: vals[:, i].astype(dt) for i, (p, dt) in enumerate(props)}
    else:
        for name, cnt, pr in elements[:vi]:
            if any(dt is None for _, dt in pr):
                raise UserError(f"{path}: cannot skip the list element {name!r} before the vertices")
            off += cnt * sum(dt.itemsize for _, dt in pr)
        st = np.dtype([(p, dt) for p, dt in props])
        if len(raw) - off < st.itemsize * n:
            raise UserError(f"{path}: truncated binary PLY: {len(raw) - off} bytes, need {st.itemsize * n}")
        arr = np.frombuffer(raw, st, n, off)
        cols = {p: np.array(arr[p]) for p, _ in props}
    xyz = np.stack([cols.pop(p) for p in "xyz"], axis=1)
    rgb = np.stack([cols.pop(p) for p in ("red", "green", "blue")], axis=1) \
        if all(p in cols for p in ("red", "green", "blue")) else None
    return make_cloud(xyz, rgb=rgb, fields=cols, path=os.fspath(path))


def write_ply(path, cloud: RealCloud, binary: bool = True) -> None:
    """Write ``cloud``'s points (flattened, NaNs kept) and colours as a PLY vertex element,
    binary little endian or ascii, atomically."""
    xyz = cloud.xyz.reshape(-1, 3).astype("<f4")
    props = [("x", xyz[:, 0]), ("y", xyz[:, 1]), ("z", xyz[:, 2])]
    if cloud.rgb is not None:
        rgb = cloud.rgb.reshape(-1, 3)
        props += [("red", rgb[:, 0]), ("green", rgb[:, 1]), ("blue", rgb[:, 2])]
    tname = lambda a: "float" if a.dtype.kind == "f" else "uchar"
    head = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", f"element vertex {len(xyz)}"]
    head += [f"property {tname(a)} {n}" for n, a in props] + ["end_header"]
    out = ("\n".join(head) + "\n").encode("ascii")
    if binary:
        rec = np.empty(len(xyz), np.dtype([(n, a.dtype) for n, a in props]))
        for n, a in props:
            rec[n] = a
        out += rec.tobytes()
    else:
        buf = io.BytesIO()
        table = np.empty((len(xyz), len(props)), object)
        for j, (_, a) in enumerate(props):
            table[:, j] = a
        np.savetxt(buf, table, fmt=["%.9g" if a.dtype.kind == "f" else "%d" for _, a in props])
        out += buf.getvalue()
    atomic_write_bytes(path, out)
