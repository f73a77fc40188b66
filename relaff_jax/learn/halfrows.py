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
  online learner whose family did not run), from the bits without a float64 copy of the
  block; the reference computes the same exact sums in one ``x @ counts.T`` of
  ``(C + 2) s R`` rows.
"""
from __future__ import annotations

import numpy as np


def _buffer(work: dict | None, key: str, shape: tuple[int, ...], dtype=np.float64) -> np.ndarray:
    """An array of ``shape`` and ``dtype`` in ``work`` (reused across blocks: a fresh 250 MB
    array per block and half costs its page faults, about a quarter of the product's time)."""
    n = int(np.prod(shape))
    if work is None:
        return np.empty(shape, dtype)
    key = (key, np.dtype(dtype).str)
    if work.get(key) is None or work[key].size < n:
        work[key] = np.empty(n, dtype)
    return work[key][:n].reshape(shape)


def row_means(bits: np.ndarray, on: np.ndarray) -> np.ndarray:
    """``(C + 2, s, R)`` float64 accuracy of every row on the half (NaN on an empty half)."""
    m = bits.shape[-1]
    if m == 0:
        return np.full((bits.shape[0] + on.shape[0],) + bits.shape[1:3], np.nan)
    counts = np.count_nonzero(bits, axis=-1).astype(np.float64)  # exact: the reference's float sum of 0/1
    return np.concatenate([counts / m, on.mean(-1)])


def resampled(bits: np.ndarray, on: np.ndarray, counts: "SceneCounts", v: np.ndarray,
              work: dict | None = None) -> np.ndarray:
    """``(B, C + 2, s)`` bootstrap means of the half: the resamples' scene counts ``counts``
    (``SceneCounts``), repetition weights ``v (B, R)``; every row's resampled accuracy is its
    exact count (``sums``) over m, then the repetitions are weighted (einsum; ``work``: arrays
    reused across calls)."""
    c, (s, r, _) = bits.shape[0] + on.shape[0], bits.shape[1:]
    per_rep = sums(bits, on, counts, work)
    per_rep /= counts.m  # accuracy per repetition and resample: one rounding, of an exact sum
    return np.einsum("csrb,br->bcs", per_rep.reshape(c, s, r, counts.b), v)


M_EXACT = 2**22  # scenes per half up to which every sum below is exact (see ``sums``)


class SceneCounts:
    """One half's resampled scene counts ``(B, m)`` (``rng.multinomial(m, ...)``, each row
    summing to m), as float64 and float32: both hold them exactly."""

    def __init__(self, counts: np.ndarray):
        counts = np.asarray(counts)
        self.b, self.m = counts.shape
        if self.m > M_EXACT:
            raise ValueError(f"a test half of {self.m} scenes: the resampled sums are exact up to {M_EXACT}")
        self.f64 = counts.astype(np.float64)
        self.f32 = counts.astype(np.float32)


def sums(bits: np.ndarray, on: np.ndarray, counts: SceneCounts, work: dict | None = None) -> np.ndarray:
    """``(M, B)`` float64: every row of the half, the conditions' 0/1 outcomes ``bits (C, s, R,
    m)`` then the online learners' ``on (2, s, R, m)`` (``M = (C + 2) s R``), times the
    resamples' counts, ``x @ counts.T``, **exact**, so the same bits in any summation order,
    on any BLAS and thread count:

    * a 0/1 row's sum of counts is an integer at most m: exact in float32 (below 2**24), so
      these rows are multiplied in float32 (about twice float64's rate), only those not all
      zero (conditions that did not run, a family that did not run: their sum is 0);
    * an online learner's row holds float32 values (a mix of tied candidates' 0/1 outcomes),
      which from 2**-7 up are multiples of 2**-30; times counts summing to m <= 2**22 every
      partial sum is a multiple of 2**-30 below 2**22, held exactly by float64's 53 bits.
      Rows with a smaller nonzero value (more than 128 candidates tied) are computed in
      float64 all the same; only there may the last bit depend on the BLAS's order.
    """
    bits, on = bits.reshape(-1, bits.shape[-1]), on.reshape(-1, on.shape[-1])
    n_bits = len(bits)
    out = _buffer(work, "per_rep", (n_bits + len(on), counts.b))
    for rows, at, dtype, c in ((bits, slice(None, n_bits), np.float32, counts.f32),
                               (on, slice(n_bits, None), np.float64, counts.f64)):
        needed = rows.any(-1)
        out[at][~needed] = 0.0
        if needed.any():
            x = _buffer(work, "rows", (int(needed.sum()), counts.m), dtype)
            x[:] = rows[needed]
            out[at][needed] = x @ c.T
    return out
