"""Per test half, what the report needs of every outcome row, from the outcomes as they are stored.

Takes one half of one target's outcomes as ``online.Outcomes.half_parts`` gives them: the
conditions' ``bits (C, s, R, m)`` bool and the online learners' ``on (2, s, R, m)`` float64;
``row_means`` gives each row's accuracy on the half ``(C + 2, s, R)`` and ``resampled`` the
bootstrap means of a block ``(B, C + 2, s)``. Both give the bits of the reference paths
(``analysis.half_curves`` / ``intervals.resampled_means`` with ``reference=True``), which
cast the whole ``(C + 2, s, R, N)`` block to float32, then to float64, then copy each half:

* a 0/1 row's mean is its count over m (the float sum of 0/1 values is that integer exactly);
  the online rows are averaged as floats, as the reference does;
* the bootstrap products are one ``x @ w.T`` of the same ``(C + 2) s R`` rows in the same
  order as the reference's: OpenBLAS computes a row differently depending on where the
  call's row partition puts it (its one-row edge kernel), so the rows are never split,
  dropped or deduplicated; the saving is in building ``x``, not in the product.
"""
from __future__ import annotations

import numpy as np


def _buffer(work: dict | None, key: str, shape: tuple[int, ...]) -> np.ndarray:
    """A float64 array of ``shape`` in ``work`` (reused across blocks: a fresh 250 MB array
    per block and half costs its page faults, about a quarter of the product's time)."""
    n = int(np.prod(shape))
    if work is None:
        return np.empty(shape, np.float64)
    if work.get(key) is None or work[key].size < n:
        work[key] = np.empty(n, np.float64)
    return work[key][:n].reshape(shape)


def rows_f64(bits: np.ndarray, on: np.ndarray, work: dict | None = None) -> np.ndarray:
    """``(C + 2, s, R, m)`` float64: the conditions' 0/1 outcomes, then the online learners'."""
    c = bits.shape[0]
    x = _buffer(work, "x", (c + on.shape[0],) + bits.shape[1:])
    x[:c] = bits
    x[c:] = on
    return x


def row_means(bits: np.ndarray, on: np.ndarray) -> np.ndarray:
    """``(C + 2, s, R)`` float64 accuracy of every row on the half (NaN on an empty half)."""
    m = bits.shape[-1]
    if m == 0:
        return np.full((bits.shape[0] + on.shape[0],) + bits.shape[1:3], np.nan)
    counts = np.count_nonzero(bits, axis=-1).astype(np.float64)  # exact: the reference's float sum of 0/1
    return np.concatenate([counts / m, on.mean(-1)])


def resampled(bits: np.ndarray, on: np.ndarray, w: np.ndarray, v: np.ndarray, work: dict | None = None) -> np.ndarray:
    """``(B, C + 2, s)`` bootstrap means of the half: scene weights ``w (B, m)``, repetition
    weights ``v (B, R)``; the reference's matmul and einsum, on the same shapes (``work``:
    arrays reused across calls)."""
    x = rows_f64(bits, on, work)
    c, s, r, m = x.shape
    per_rep = _buffer(work, "per_rep", (c * s * r, len(w)))
    np.matmul(x.reshape(-1, m), w.T, out=per_rep)  # accuracy per repetition and resample
    return np.einsum("csrb,br->bcs", per_rep.reshape(c, s, r, len(w)), v)
