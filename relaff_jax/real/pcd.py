"""PCD v0.7 (Point Cloud Library) files: ``read_pcd`` and ``write_pcd``.

Takes a ``.pcd`` path (``DATA ascii``, ``binary`` or ``binary_compressed``, any FIELDS / SIZE /
TYPE / COUNT); gives a ``RealCloud`` (xyz (H, W, 3) when HEIGHT > 1, else (N, 3); a ``rgb`` or
``rgba`` field unpacked to uint8 colour; ``label`` as uint32; every other field kept in
``fields``; intrinsics estimated for organized clouds). ``write_pcd`` writes the same formats
atomically. binary_compressed: header, then uint32 compressed size, uint32 uncompressed size,
then LZF data whose decompression is the fields column-major (all points' values of the first
field, then of the second, ...).
"""
from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.io import atomic_write_bytes

from . import lzf
from .cloud import RealCloud, make_cloud, pack_rgb, unpack_rgb

_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4",
          ("I", 8): "<i8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}
_DATA = ("ascii", "binary", "binary_compressed")
_PAD = b"\x00 \t\r\n"  # what may follow the data: PCL's zero padding, a final newline


def _header(raw: bytes, path) -> tuple[dict, int]:
    """Parse the header lines up to DATA; returns (fields dict, byte offset of the data)."""
    h, pos = {}, 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise UserError(f"{path}: truncated PCD header (no DATA line)")
        line = raw[pos:end].decode("ascii", "replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        h[key.upper()] = vals
        if key.upper() == "DATA":
            return h, pos


def _layout(h: dict, path) -> tuple[list, list, int, int]:
    """(names, numpy dtypes, counts) and width, height of a parsed header, checked."""
    names = h.get("FIELDS")
    if not names:
        raise UserError(f"{path}: PCD header has no FIELDS line")
    n = len(names)
    sizes = h.get("SIZE", [])
    types = h.get("TYPE", [])
    counts = h.get("COUNT", ["1"] * n)
    if not (len(sizes) == len(types) == len(counts) == n):
        raise UserError(f"{path}: FIELDS ({n}), SIZE ({len(sizes)}), TYPE ({len(types)}) and "
                        f"COUNT ({len(counts)}) must have one entry per field")
    dts = []
    try:
        sizes, counts = [int(s) for s in sizes], [int(c) for c in counts]
    except ValueError:
        raise UserError(f"{path}: SIZE and COUNT must be integers, got {' '.join(map(str, sizes))} and "
                        f"{' '.join(map(str, counts))}") from None
    if min(counts) < 1:
        raise UserError(f"{path}: COUNT must be >= 1 for every field, got {' '.join(map(str, counts))}")
    for name, s, t in zip(names, sizes, types):
        dt = _TYPES.get((t.upper(), s))
        if dt is None:
            raise UserError(f"{path}: field {name!r} has unsupported TYPE {t} SIZE {s}")
        dts.append(np.dtype(dt))
    try:
        width = int(h.get("WIDTH", ["0"])[0])
        height = int(h.get("HEIGHT", ["1"])[0])
        points = int(h.get("POINTS", [str(width * height)])[0])
    except (ValueError, IndexError):
        raise UserError(f"{path}: WIDTH, HEIGHT and POINTS must be integers") from None
    if min(width, height, points) < 0:
        raise UserError(f"{path}: WIDTH, HEIGHT and POINTS must be >= 0, got {width}, {height}, {points}")
    if width * height != points:
        raise UserError(f"{path}: WIDTH x HEIGHT = {width * height} but POINTS = {points}")
    for name in ("x", "y", "z"):
        if name not in names:
            raise UserError(f"{path}: PCD has no {name!r} field (FIELDS: {' '.join(names)})")
    return list(zip(names, dts, counts)), width, height


def _columns(layout, raw: bytes, off: int, mode: str, npts: int, path) -> dict:
    """name -> (npts, count) array from the data section."""
    if mode == "ascii":
        width = sum(c for _, _, c in layout)
        tokens = raw[off:].split()
        if len(tokens) < npts * width:
            raise UserError(f"{path}: truncated ascii data: {len(tokens)} values, need {npts} x {width}")
        if len(tokens) > npts * width:  # the header's POINTS is wrong, or two files were joined
            raise UserError(f"{path}: {len(tokens)} ascii values, but the header's {npts} points x {width} "
                            f"values make {npts * width}: POINTS (WIDTH x HEIGHT) does not match the data")
        try:  # float64 holds every 32-bit integer exactly; "nan" parses
            vals = np.array(tokens[:npts * width]).astype(np.float64).reshape(npts, width)
        except ValueError:
            raise UserError(f"{path}: ascii data holds a value that is not a number") from None
        out, k = {}, 0
        for name, dt, c in layout:
            out[name] = vals[:, k:k + c].astype(dt)
            k += c
        return out
    rec = sum(dt.itemsize * c for _, dt, c in layout)
    if mode == "binary":
        need = rec * npts
        if len(raw) - off < need:
            raise UserError(f"{path}: truncated binary data: {len(raw) - off} bytes, need {need}")
        if raw[off + need:].strip(_PAD):
            raise UserError(f"{path}: {len(raw) - off - need} bytes after the header's {npts} points x {rec} bytes: "
                            "POINTS (WIDTH x HEIGHT) does not match the data")
        st = np.dtype([(f"f{i}", dt, (c,)) for i, (_, dt, c) in enumerate(layout)])
        arr = np.frombuffer(raw, dtype=st, count=npts, offset=off)
        return {name: np.array(arr[f"f{i}"]).reshape(npts, c) for i, (name, _, c) in enumerate(layout)}
    if len(raw) - off < 8:
        raise UserError(f"{path}: truncated binary_compressed data (no size words)")
    csize, usize = (int(v) for v in np.frombuffer(raw, "<u4", 2, off))
    if usize != rec * npts:
        raise UserError(f"{path}: uncompressed size {usize} does not match the header ({npts} points x "
                        f"{rec} bytes = {rec * npts})")
    if len(raw) - off - 8 < csize:
        raise UserError(f"{path}: truncated binary_compressed data: {len(raw) - off - 8} of {csize} bytes")
    if raw[off + 8 + csize:].strip(_PAD):  # PCL pads its files with zero bytes: those are fine
        raise UserError(f"{path}: {len(raw) - off - 8 - csize} bytes that are not padding after the compressed data ({csize} bytes, "
                        "as its size word says): a damaged or joined file")
    buf = lzf.decompress(raw[off + 8:off + 8 + csize], usize)
    out, k = {}, 0
    for name, dt, c in layout:
        nb = dt.itemsize * c * npts
        out[name] = np.frombuffer(buf, dtype=dt, count=c * npts, offset=k).reshape(npts, c).copy()
        k += nb
    return out


def read_pcd(path) -> RealCloud:
    """Read a PCD v0.7 file into a ``RealCloud`` (see the module docstring); UserError for a
    truncated file, an unknown DATA kind, mismatched sizes or a missing x/y/z field."""
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise UserError(f"cannot read {path}: {e.strerror}") from None
    h, off = _header(raw, path)
    mode = (h["DATA"] or [""])[0].lower()
    if mode not in _DATA:
        raise UserError(f"{path}: unknown DATA {mode!r}; valid: {', '.join(_DATA)}")
    layout, width, height = _layout(h, path)
    npts = width * height
    cols = _columns(layout, raw, off, mode, npts, path)
    shape = (height, width) if height > 1 else (npts,)
    xyz = np.concatenate([cols.pop(n)[:, :1] for n in ("x", "y", "z")], axis=1).astype(np.float32)
    rgb = None
    for name in ("rgb", "rgba"):
        if name in cols and rgb is None and cols[name].shape[1] == 1 and cols[name].dtype.itemsize == 4:
            rgb = unpack_rgb(cols.pop(name)[:, 0]).reshape(shape + (3,))
    label = cols.pop("label")[:, 0].reshape(shape) if "label" in cols and cols["label"].shape[1] == 1 else None
    fields = {n: v[:, 0].reshape(shape) if v.shape[1] == 1 else v.reshape(shape + (v.shape[1],))
              for n, v in cols.items()}
    vp = h.get("VIEWPOINT")
    try:
        vp = [float(v) for v in vp] if vp else None
    except ValueError:
        raise UserError(f"{path}: VIEWPOINT must be 7 numbers, got {' '.join(vp)!r:.60}") from None
    if vp is not None and (len(vp) != 7 or not np.all(np.isfinite(vp))):
        raise UserError(f"{path}: VIEWPOINT must be 7 finite numbers (tx ty tz qw qx qy qz), got {len(vp)}")
    return make_cloud(xyz.reshape(shape + (3,)), rgb=rgb, label=label, fields=fields,
                      viewpoint=vp, path=os.fspath(path))


def write_pcd(path, cloud: RealCloud, data: str = "binary_compressed") -> None:
    """Write ``cloud`` (xyz, rgb as a uint32 ``rgba`` field, label, 1-D ``fields``) as PCD v0.7
    ``data`` in {"ascii", "binary", "binary_compressed"}, atomically."""
    if data not in _DATA:
        raise UserError(f"unknown PCD DATA {data!r}; valid: {', '.join(_DATA)}")
    lead = cloud.xyz.shape[:-1]
    npts = int(np.prod(lead))
    height, width = (lead if len(lead) == 2 else (1, npts))
    cols = []
    if cloud.label is not None:
        cols.append(("label", cloud.label.reshape(npts).astype("<u4")))
    for i, n in enumerate("xyz"):
        cols.append((n, cloud.xyz[..., i].reshape(npts).astype("<f4")))
    if cloud.rgb is not None:
        cols.append(("rgba", pack_rgb(cloud.rgb).reshape(npts).astype("<u4")))
    for n, v in cloud.fields.items():
        v = np.asarray(v).reshape(npts, -1)
        if v.shape[1] != 1:
            raise UserError(f"write_pcd writes one value per point per field; {n!r} has {v.shape[1]}")
        cols.append((n, v[:, 0].astype(v.dtype.newbyteorder("<"))))
    kind = lambda a: "F" if a.dtype.kind == "f" else ("I" if a.dtype.kind == "i" else "U")
    head = ["# .PCD v0.7 - Point Cloud Data file format", "VERSION 0.7",
            "FIELDS " + " ".join(n for n, _ in cols), "SIZE " + " ".join(str(a.itemsize) for _, a in cols),
            "TYPE " + " ".join(kind(a) for _, a in cols), "COUNT " + " ".join("1" for _ in cols),
            f"WIDTH {width}", f"HEIGHT {height}",
            "VIEWPOINT " + " ".join(f"{v:g}" for v in (cloud.viewpoint or (0, 0, 0, 1, 0, 0, 0))),
            f"POINTS {npts}", f"DATA {data}"]
    out = ("\n".join(head) + "\n").encode("ascii")
    if data == "ascii":  # %.9g round-trips float32, %.17g float64; NaN prints as nan
        buf = io.BytesIO()
        fmts = ["%.17g" if a.dtype == np.float64 else "%.9g" if a.dtype.kind == "f" else "%d" for _, a in cols]
        table = np.empty((npts, len(cols)), object)
        for j, (_, a) in enumerate(cols):
            table[:, j] = a
        np.savetxt(buf, table, fmt=fmts)
        out += buf.getvalue()
    elif data == "binary":
        st = np.dtype([(n, a.dtype) for n, a in cols])
        rec = np.empty(npts, st)
        for n, a in cols:
            rec[n] = a
        out += rec.tobytes()
    else:
        raw = b"".join(a.tobytes() for _, a in cols)
        comp = lzf.compress(raw)
        out += np.array([len(comp), len(raw)], "<u4").tobytes() + comp
    atomic_write_bytes(path, out)
