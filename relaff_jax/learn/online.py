"""The online "best after ten": per repetition, the candidate an agent would keep after ten samples.

Takes one space's results (``acc: (A, C, S, R)``, ``loo: (A, C, R)`` the leave-one-out
accuracy of every DB1 and CB1 candidate on its own ``select_size`` training samples,
``correct: (A, C, S, R, N)``) and the condition layout; ``online_weights`` gives per family,
target and repetition the weight of each candidate ``(A, K, R)``: the candidates tied at the
highest leave-one-out accuracy share it equally (``measures.tie_weights``: a tie is a uniform
random choice; with ten samples the accuracy moves in steps of 0.1, so ties are common).
``extend`` appends the two chosen learners (DB1, CB1) to the condition axis as the
weighted mix of the candidates' accuracies and test outcomes, ``(A, C + 2, S, R)`` and
``(A, C + 2, S, R, N)`` float, so that every later step (means, intervals, Table II) treats
them like conditions (``Outcomes.half_parts``: one half of a block as the report's
resampling reads it, ``halfrows``). The choice never looks at a test scene, unlike the
paper's (offline) "best after ten", which picks the candidate with the highest mean test
accuracy at n = 10.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from relaff_jax.learn.measures import tie_weights

FAMILIES = ("DB1", "CB1")  # in the order of the extra conditions


def online_weights(loo: np.ndarray, lay: Mapping) -> dict[str, np.ndarray]:
    """``{family: (A, K, R)}`` weights of the online choice from ``loo: (A, C, R)``."""
    loo = np.asarray(loo, dtype=float)
    return {fam: np.moveaxis(tie_weights(np.moveaxis(loo[:, lay[fam]], 1, -1)), -1, 1) for fam in FAMILIES}


def _mix(x: np.ndarray, idx: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``x (A, C, S, R, ...)``, weights ``w (A, K, R)`` over conditions ``idx`` -> ``(A, S, R, ...)``."""
    xs = np.nan_to_num(np.asarray(x)[:, idx].astype(float))  # (A, K, S, R, ...)
    ww = w.reshape(w.shape[:2] + (1,) + w.shape[2:] + (1,) * (xs.ndim - 4))
    total = w.sum(1)  # (A, R): 1 where a choice was made, 0 where the family did not run
    out = (xs * ww).sum(1)
    ok = total.reshape(total.shape[:1] + (1,) + total.shape[1:] + (1,) * (xs.ndim - 4)) > 0
    return np.where(ok, out, np.nan)


def _mix_sparse(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``_mix`` of one target, nonzero weights only: candidates' outcomes ``x (K, s, R, m)``
    (0/1, any dtype), ``w (K, R)`` -> ``(s, R, m)`` float64, 0 where no candidate has weight
    (``_mix`` then ``nan_to_num``). The same bits: ``_mix`` adds the K products in order and
    the skipped ones are +0.0, which leave a sum of nonnegative terms unchanged."""
    out = np.zeros((x.shape[1], x.shape[2], x.shape[3]), np.float64)
    for r in range(w.shape[1]):
        ks = np.flatnonzero(w[:, r])  # increasing: _mix's order
        if len(ks):
            acc = x[ks[0], :, r] * w[ks[0], r]
            for k in ks[1:]:
                acc = acc + x[k, :, r] * w[k, r]
            out[:, r] = acc
    return out


def extend(acc: np.ndarray, correct: np.ndarray, loo: np.ndarray, lay: Mapping) -> tuple[np.ndarray, "Outcomes", dict]:
    """``acc (A, C + 2, S, R)`` with the online learners appended (NaN where a family did not
    run), their outcomes as ``Outcomes`` (``(A, C + 2, S, R, N)`` float32, made one target and
    block of sizes at a time) and the weights."""
    w = online_weights(loo, lay)
    acc_on = np.stack([_mix(acc, lay[f], w[f]) for f in FAMILIES], 1)
    acc_x = np.concatenate([np.asarray(acc, dtype=float), acc_on], 1)
    return acc_x, Outcomes(correct if hasattr(correct, "shape") else np.asarray(correct), w, lay), w


class Outcomes:
    """The outcomes of every condition and of the two online learners, ``(A, C + 2, S, R, N)``
    float32, never held whole: the paper preset's would be 37 GB (9 x 52 x 99 x 50 x 4,000).
    ``block(t, sizes)`` gives target ``t``'s ``(C + 2, len(sizes), R, N)``, the same bits as
    slicing the whole array (the mix is elementwise over sizes and scenes)."""

    def __init__(self, correct: np.ndarray, w: Mapping[str, np.ndarray], lay: Mapping, budget: float = 2.5e8):
        self.correct, self.w, self.lay, self.budget = correct, w, lay, budget
        a, c, s, r, n = correct.shape
        self.shape = (a, c + len(FAMILIES), s, r, n)

    def block(self, t: int, sizes: slice | np.ndarray = slice(None)) -> np.ndarray:
        corr = np.asarray(self.correct[t : t + 1, :, sizes])  # (1, C, s, R, N)
        on = np.stack([np.nan_to_num(_mix(corr, self.lay[f], self.w[f][t : t + 1])) for f in FAMILIES], 1)
        return np.concatenate([corr.astype(np.float32), on.astype(np.float32)], 1)[0]

    def half_parts(self, t: int, sizes: slice, cols: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per test-scene index set ``cols[h] (m_h,)``: the conditions' outcomes ``(C, s, R, m_h)``
        bool and the online learners' ``(2, s, R, m_h)`` float64, the same values as
        ``block(t, sizes)[..., cols[h]]`` (the online ones through float32, as ``block``)
        without the float copies of the whole block; the mix only over the chosen candidates
        (``_mix_sparse``) and the scenes of the half."""
        corr = np.asarray(self.correct[t : t + 1, :, sizes])[0]  # (C, s, R, N) bool, unpacked once
        out = []
        for idx in cols:
            x = np.take(corr, idx, axis=-1).astype(bool, copy=False)  # ~5x the fancy index's speed here
            on = np.stack([_mix_sparse(x[self.lay[f]], self.w[f][t]) for f in FAMILIES])
            out.append((x, on.astype(np.float32).astype(np.float64)))
        return out

    def size_blocks(self) -> list[slice]:
        """Slices of the size axis whose float32 block of one target stays under ``budget`` bytes."""
        _, c, s, r, n = self.shape
        step = max(1, int(self.budget // max(1, 4 * c * r * n)))
        return [slice(i, min(i + step, s)) for i in range(0, s, step)]
