"""Per test half, what the report needs of every outcome row, from the outcomes as they are stored.

Takes one half of one target's outcomes as ``online.Outcomes.half_parts`` gives them: the
conditions' ``bits (C, s, R, m)`` bool and the online learners' ``on (2, s, R, m)`` float64;
``row_means`` gives each row's accuracy on the half ``(C + 2, s, R)`` and ``resampled`` the
bootstrap means of a block ``(B, C + 2, s)``. Both give the bits of the reference paths
(``analysis.half_curves`` / ``intervals.resampled_means`` with ``reference=True``), which
cast the whole ``(C + 2, s, R, N)`` block to float32, then to float64, then copy each half:

* a 0/1 row's mean is its count over m (the float sum of 0/1 values is that integer exactly);
  the online rows are averaged as floats, as the reference does;
* a resample's accuracy of a row is the row's exact sum of the resample's scene counts
  (``sums``: integers, or multiples of 2**-30 for the online rows, exact in any order) over
  m, computed for the rows that are not all zero only (conditions that did not run, an
  online learner whose family did not run); the reference computes the same exact sums in
  one ``x @ counts.T`` of ``(C + 2) s R`` rows.
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


class Rows:
    """The rows of ``rows_f64(bits, on)`` as ``(M, m)`` without the float64 copy of them all
    (most of a block's bytes): the conditions' 0/1 rows as bits ``(C s R, m)`` and the online
    learners' ``(2 s R, m)``, in ``rows_f64``'s order."""

    def __init__(self, bits: np.ndarray, on: np.ndarray, work: dict | None = None):
        self.b4, self.o4, self.work = bits, on, work
        self.bits, self.on = bits.reshape(-1, bits.shape[-1]), on.reshape(-1, on.shape[-1])
        self.shape = (len(self.bits) + len(self.on), self.bits.shape[1])

    def __len__(self) -> int:
        return self.shape[0]

    def whole(self) -> np.ndarray:
        """All of them, as ``rows_f64`` gives them."""
        return rows_f64(self.b4, self.o4, self.work).reshape(self.shape)


def resampled(bits: np.ndarray, on: np.ndarray, counts: "SceneCounts", v: np.ndarray,
              work: dict | None = None) -> np.ndarray:
    """``(B, C + 2, s)`` bootstrap means of the half: the resamples' scene counts ``counts``
    (``SceneCounts``), repetition weights ``v (B, R)``; every row's resampled accuracy is its
    exact count (``sums``, of the rows read from the bits, ``Rows``) over m, then the
    repetitions are weighted (einsum; ``work``: arrays reused across calls)."""
    c, (s, r, _) = bits.shape[0] + on.shape[0], bits.shape[1:]
    per_rep = sums(Rows(bits, on, work), counts, work)
    per_rep /= counts.m  # accuracy per repetition and resample: one rounding, of an exact sum
    return np.einsum("csrb,br->bcs", per_rep.reshape(c, s, r, counts.b), v)


F32_EXACT = 2**24  # float32 holds every integer up to this: a 0/1 row's sum of counts is at most m


class SceneCounts:
    """One half's resampled scene counts ``(B, m)`` (``rng.multinomial(m, ...)``, each row
    summing to m), as float64 and float32: both hold them exactly (m < 2**24)."""

    def __init__(self, counts: np.ndarray):
        counts = np.asarray(counts)
        self.b, self.m = counts.shape
        self.f64 = counts.astype(np.float64)
        self.f32 = counts.astype(np.float32) if self.m <= F32_EXACT else None


def sums(x, counts: SceneCounts, work: dict | None = None) -> np.ndarray:
    """``(M, B)`` float64: every row of ``x`` (``Rows``, or an ``(M, m)`` array of the same
    values) times the resamples' counts, ``x @ counts.T``, **exact**, so the same bits in any
    summation order, on any BLAS and thread count:

    * a 0/1 row's sum of counts is an integer at most m: exact in float32 up to 2**24, so
      these rows are multiplied in float32 (twice float64's rate), only those not all zero
      (conditions that did not run, a family that did not run: their sum is 0);
    * an online learner's row holds float32 values (a mix of tied candidates' 0/1 outcomes),
      which from 2**-7 up are multiples of 2**-30; times counts summing to m <= 2**22 every
      partial sum is a multiple of 2**-30 below 2**22, held exactly by float64's 53 bits.
      Rows with a smaller nonzero value (more than 128 candidates tied) are computed in
      float64 all the same; only there may the last bit depend on the BLAS's order.
    """
    rows = x if isinstance(x, Rows) else None
    arr = None if rows is not None else np.asarray(x, dtype=np.float64)
    n_rows = len(rows) if rows is not None else len(arr)
    out = _buffer(work, "per_rep", (n_rows, counts.b))
    if rows is None:
        needed = arr.any(-1)
        out[~needed] = 0.0
        out[needed] = arr[needed] @ counts.f64.T
        return out
    n_bits = len(rows.bits)
    needed = rows.bits.any(-1)
    out[:n_bits][~needed] = 0.0
    if needed.any():
        if counts.f32 is not None:
            buf = _buffer32(work, "rows", (int(needed.sum()), counts.m))
            buf[:] = rows.bits[needed]
            out[:n_bits][needed] = buf @ counts.f32.T
        else:
            out[:n_bits][needed] = rows.bits[needed].astype(np.float64) @ counts.f64.T
    on_needed = rows.on.any(-1)
    out[n_bits:][~on_needed] = 0.0
    if on_needed.any():
        out[n_bits:][on_needed] = rows.on[on_needed] @ counts.f64.T
    return out


def _buffer32(work: dict | None, key: str, shape: tuple[int, ...]) -> np.ndarray:
    """``_buffer``'s float32 twin."""
    n = int(np.prod(shape))
    if work is None:
        return np.empty(shape, np.float32)
    key = key + "32"
    if work.get(key) is None or work[key].size < n:
        work[key] = np.empty(n, np.float32)
    return work[key][:n].reshape(shape)
