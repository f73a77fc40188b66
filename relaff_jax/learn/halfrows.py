"""Per test half, what the report needs of every outcome row, from the outcomes as they are stored.

Takes one half of one target's outcomes as ``online.Outcomes.half_parts`` gives them: the
conditions' ``bits (C, s, R, m)`` bool and the online learners' ``on (2, s, R, m)`` float64;
``row_means`` gives each row's accuracy on the half ``(C + 2, s, R)`` and ``resampled`` the
bootstrap means of a block ``(B, C + 2, s)``. Both give the bits of the reference paths
(``analysis.half_curves`` / ``intervals.resampled_means`` with ``reference=True``), which
cast the whole ``(C + 2, s, R, N)`` block to float32, then to float64, then copy each half:

* a 0/1 row's mean is its count over m (the float sum of 0/1 values is that integer exactly);
  the online rows are averaged as floats, as the reference does;
* the bootstrap products have the bits of the reference's one ``x @ w.T`` of ``(C + 2) s R``
  rows, computed for the rows that are not all zero only (conditions that did not run, an
  online learner whose family did not run): ``products``, which keeps every row on the kind of
  BLAS kernel the reference's call computes it with.
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
    """The rows of ``rows_f64(bits, on)`` as ``(M, m)``, read where ``products`` needs them
    without the float64 copy of them all (most of a block's bytes): ``take`` gathers bits, 1
    byte each, and casts them (0/1: the same values)."""

    def __init__(self, bits: np.ndarray, on: np.ndarray, work: dict | None = None):
        self.b4, self.o4, self.work = bits, on, work
        self.bits, self.on = bits.reshape(-1, bits.shape[-1]), on.reshape(-1, on.shape[-1])
        self.shape = (len(self.bits) + len(self.on), self.bits.shape[1])

    def __len__(self) -> int:
        return self.shape[0]

    def take(self, rows: np.ndarray, out: np.ndarray) -> None:
        """``out[:] = x[rows]``, ``rows`` increasing."""
        k = int(np.searchsorted(rows, len(self.bits)))
        out[:k] = np.take(self.bits, rows[:k], axis=0)
        out[k:] = np.take(self.on, rows[k:] - len(self.bits), axis=0)

    def row(self, i: int) -> np.ndarray:
        return self.bits[i] if i < len(self.bits) else self.on[i - len(self.bits)]

    def whole(self) -> np.ndarray:
        """All of them, as ``rows_f64`` gives them (the one call's fallback)."""
        return rows_f64(self.b4, self.o4, self.work).reshape(self.shape)


def resampled(bits: np.ndarray, on: np.ndarray, w: np.ndarray, v: np.ndarray, work: dict | None = None) -> np.ndarray:
    """``(B, C + 2, s)`` bootstrap means of the half: scene weights ``w (B, m)``, repetition
    weights ``v (B, R)``; the reference's products (``products``, of the rows read from the
    bits, ``Rows``) and einsum (``work``: arrays reused across calls)."""
    c, (s, r, _) = bits.shape[0] + on.shape[0], bits.shape[1:]
    needed = np.concatenate([bits.any(-1), on.any(-1)]).reshape(-1)  # an all-zero row's product is +0 in any order
    per_rep = products(Rows(bits, on, work), w, needed, work)  # accuracy per repetition and resample
    return np.einsum("csrb,br->bcs", per_rep.reshape(c, s, r, len(w)), v)


_KINDS: dict = {}  # probed call shapes (rows, B, m) -> rows computed apart, and how to compute one so
_CLEAN = 256  # the rows of our own calls are rounded up to a multiple of this (fewer shapes to probe)


def products(x: np.ndarray, w: np.ndarray, needed: np.ndarray, work: dict | None = None) -> np.ndarray:
    """``x @ w.T`` ``(M, B)`` of ``x (M, m)`` and ``w (B, m)`` with the bits of that one call,
    computing only the ``needed (M,)`` rows (the others must be all zero: their product is 0).

    OpenBLAS splits a call's rows into parts (by thread) and computes the last row of a part of
    odd length with its one-row edge kernel, whose sum differs in the last bit from the other
    rows' (``M = 1300``: rows 324, 649, 974 and 1299). ``_kinds`` probes each call shape once
    (one 0/1 row repeated M times) for the rows it computes apart; the other needed rows are
    computed in a call of a shape that has none, the apart ones one by one at an apart place of
    a small call. Where a probe finds anything else (more than two kinds of rows, no small call
    with an apart row of the same bits), the one call of ``M`` rows, as the reference."""
    out = _buffer(work, "per_rep", (len(x), len(w)))
    kinds = _kinds(len(x), w)
    n_common = int((needed & ~kinds[0]).sum()) if kinds else 0
    clean = _clean_rows(n_common, w) if kinds else None
    if kinds is None or clean is None:
        return np.matmul(x.whole() if isinstance(x, Rows) else x, w.T, out=out)
    apart, small, at = kinds
    out[:] = 0.0
    rows = np.flatnonzero(needed & ~apart)
    if len(rows):
        buf = _buffer(work, "common", (clean, x.shape[1]))
        buf[len(rows):] = 0.0
        if isinstance(x, Rows):
            x.take(rows, buf[: len(rows)])
        else:
            np.take(x, rows, axis=0, out=buf[: len(rows)])
        out[rows] = (buf @ w.T)[: len(rows)]
    for i in np.flatnonzero(needed & apart):
        one = np.zeros((small, x.shape[1]))
        one[at] = x.row(i) if isinstance(x, Rows) else x[i]
        out[i] = (one @ w.T)[at]
    return out


def _threads() -> tuple:
    """The BLAS libraries' thread counts: the row split, hence the probed kinds, depend on them."""
    try:
        from threadpoolctl import threadpool_info  # noqa: PLC0415 (scikit-learn's dependency)
    except ImportError:
        return ()
    return tuple(i.get("num_threads") for i in threadpool_info() if i.get("user_api") == "blas")


def _probe(rows: int, w: np.ndarray) -> np.ndarray:
    """``(rows, B)``: one fixed 0/1 row repeated ``rows`` times, times ``w.T`` in one call."""
    row = np.random.default_rng(0).random(w.shape[1]) < 0.5
    return np.tile(row.astype(np.float64), (rows, 1)) @ w.T


def _kinds(rows: int, w: np.ndarray):
    """For a call of ``rows`` rows against ``w``: ``(apart (rows,) bool, small, at)`` (the rows
    computed apart, and a call of ``small`` rows computing its row ``at`` the same way), or None."""
    key = ("kinds", rows, _threads()) + w.shape
    if key not in _KINDS:
        p = _probe(rows, w)
        common = _probe(8, w)
        if not (common == common[0]).all():
            _KINDS[key] = None
            return None
        apart = ~(p == common[0]).all(1)
        found = (apart, 1, 0) if not apart.any() else None
        if apart.any() and (p[apart] == p[apart][0]).all():
            for small in range(2, 17):  # the first small call with an apart row of the same bits
                q = _probe(small, w)
                hit = np.flatnonzero((q == p[apart][0]).all(1) & ~(q == common[0]).all(1))
                if len(hit):
                    found = (apart, small, int(hit[0]))
                    break
        _KINDS[key] = found
    return _KINDS[key]


def _clean_rows(n: int, w: np.ndarray) -> int | None:
    """The rows (``>= n``, a multiple of ``_CLEAN``) of a call that computes none apart, or None."""
    for rows in range(max(_CLEAN, -(-n // _CLEAN) * _CLEAN), -(-n // _CLEAN) * _CLEAN + 4 * _CLEAN, _CLEAN):
        key = ("clean", rows, _threads()) + w.shape
        if key not in _KINDS:
            k = _kinds(rows, w)
            _KINDS[key] = k is not None and not k[0].any()
        if _KINDS[key]:
            return rows
    return None
