"""LZF (liblzf) decompression and compression for PCD ``DATA binary_compressed``.

Takes LZF bytes and the expected decompressed size; gives the decompressed bytes. Uses the
C extension ``python-lzf`` (a dependency: ~10 ms for a 6 MB Kinect scene) and falls back to a
pure-Python decoder (~1 s per scene) where it cannot be imported. ``decompress_py`` is also
the independent reference the tests check the C path against.

LZF stream: a control byte c; c < 32: a literal run of c + 1 bytes follows; otherwise a back
reference of length (c >> 5) + 2 (when c >> 5 == 7, plus the next byte) at distance
((c & 31) << 8 | next byte) + 1 before the output's end (it may overlap what it writes).
"""
from __future__ import annotations

from relaff_jax.errors import UserError

try:  # the fast path
    import lzf as _clzf
except ImportError:  # pragma: no cover - exercised only without the dependency
    _clzf = None


def decompress_py(data: bytes, size: int) -> bytes:
    """Pure-Python LZF decoder; ``size``: the decompressed size. Raises UserError on a
    corrupt stream (a reference before the start, a run past the end, a size mismatch)."""
    src = memoryview(bytes(data))
    out = bytearray(size)
    i = o = 0
    n = len(src)
    while i < n:
        c = src[i]
        i += 1
        if c < 32:
            run = c + 1
            if i + run > n or o + run > size:
                raise UserError("corrupt LZF data: a literal run goes past the end")
            out[o:o + run] = src[i:i + run]
            i += run
            o += run
            continue
        length = c >> 5
        if length == 7:
            if i >= n:
                raise UserError("corrupt LZF data: truncated back reference")
            length += src[i]
            i += 1
        if i >= n:
            raise UserError("corrupt LZF data: truncated back reference")
        ref = o - ((c & 31) << 8) - src[i] - 1
        i += 1
        length += 2
        if ref < 0 or o + length > size:
            raise UserError("corrupt LZF data: a back reference outside the output")
        dist = o - ref
        if dist >= length:
            out[o:o + length] = out[ref:ref + length]
        else:  # overlapping copy: the pattern of the last ``dist`` bytes repeats
            pat = bytes(out[ref:o])
            reps = pat * (length // dist + 1)
            out[o:o + length] = reps[:length]
        o += length
    if o != size:
        raise UserError(f"corrupt LZF data: decompressed to {o} bytes, the header says {size}")
    return bytes(out)


def decompress(data: bytes, size: int) -> bytes:
    """Decompress LZF ``data`` to exactly ``size`` bytes (C path if available); UserError if the
    stream is corrupt or does not decompress to ``size`` bytes."""
    if size == 0:
        return b""
    if _clzf is None:
        return decompress_py(data, size)
    try:
        out = _clzf.decompress(bytes(data), size)
    except ValueError as e:
        raise UserError(f"corrupt LZF data: {e}") from None
    if out is None or len(out) != size:
        raise UserError(f"corrupt LZF data: it does not decompress to the {size} bytes the header says")
    return out


def compress(data: bytes) -> bytes:
    """LZF-compress ``data`` (needs the C extension; an incompressible buffer is stored as
    literal runs, which any LZF decoder reads)."""
    data = bytes(data)
    if _clzf is not None and data:
        out = _clzf.compress(data, len(data) + len(data) // 16 + 64)
        if out is not None:
            return out
    # Literal runs only: valid LZF, no compression.
    parts = []
    for k in range(0, len(data), 32):
        chunk = data[k:k + 32]
        parts.append(bytes([len(chunk) - 1]) + chunk)
    return b"".join(parts)
