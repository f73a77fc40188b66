"""``measures._mix``'s weighted sum over candidates, compiled (numba): one pass over the cells.

``weighted_sums(cells (L, A, K, S), w (L, A, K)) -> (L, A, S)``: per (l, a, s) the sum over k
of ``(cells if w > 0 else 0.0) * w``, added in k's order from the first candidate's product.
That is the order of numpy's ``(np.where(w > 0, cells, 0) * w).sum(-2)`` when ``S >= 2``:
numpy reduces a non-innermost axis one slice after another (with ``S == 1`` it would sum
the candidates pairwise; ``measures._mix`` keeps numpy's own path there). numba adds and
multiplies in IEEE order without contraction into fused multiply-adds (no ``fastmath``), so the
bits are numpy's; numpy makes three temporaries of the whole block for it, this reads it once.

Imported on first use: numba loads the kernel from its on-disk cache (``cache=True``), or
compiles it (about half a second) on a new install, when this module is imported.
"""
from __future__ import annotations

import numba
import numpy as np


# one signature of any-layout arrays: one compile on a new install, for contiguous cells and slices alike
@numba.njit("f8[:, :, :](f8[:, :, :, :], f8[:, :, :])", cache=True, nogil=True)
def weighted_sums(cells: np.ndarray, w: np.ndarray) -> np.ndarray:  # pragma: no cover (compiled)
    n_l, n_a, n_k, n_s = cells.shape
    out = np.empty((n_l, n_a, n_s))
    for i in range(n_l):
        for a in range(n_a):
            wk = w[i, a, 0]
            for s in range(n_s):  # the first candidate's product starts the sum, as numpy's
                out[i, a, s] = (cells[i, a, 0, s] if wk > 0 else 0.0) * wk
            for k in range(1, n_k):
                wk = w[i, a, k]
                for s in range(n_s):
                    out[i, a, s] += (cells[i, a, k, s] if wk > 0 else 0.0) * wk
    return out
