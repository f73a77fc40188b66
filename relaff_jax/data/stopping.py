"""When generation stops and which rollouts a selection may take.

Takes the stored chunks' labels, COG distances and eligibility, and the dataset node
(``DatasetConfig``); gives each chunk's eligible rollouts (``eligible_rows``: the population, less
the rollouts never at rest under ``unsettled="refuse"``), whether a run stops at k chunks
(``stops``) and the first stored chunk count at which a run of a scheme would have stopped
(``first_stop``: a folder selected again under a new scheme becomes the dataset a run of that
scheme makes from the start). Pure functions over numpy arrays; ``generate`` drives them.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.data.errors import DatasetError
from relaff_jax.data.selection import select_balanced


def eligible_rows(arrays: Mapping[str, Any], dcfg: DatasetConfig, where: str) -> tuple[np.ndarray, int | None]:
    """(B,) bool: the rollouts of a chunk the selection may take (the population, less the
    unsettled ones under ``unsettled="refuse"``), and how many the population admits but the
    rest rule refuses (None: the rollouts do not say whether they settled, so none is refused)."""
    label = np.asarray(arrays["label"])
    ok = np.ones(label.shape, bool)
    if dcfg.population != "all":
        if "feasible" not in arrays:
            raise DatasetError(f"{where} has no 'feasible' field, which dataset.population={dcfg.population!r} needs "
                               f"(the rollout function must return whether each motor program was executable)")
        ok = np.asarray(arrays["feasible"], bool)
    if dcfg.unsettled == "keep":
        return ok, 0
    if "settled" not in arrays:  # a rollout function without a rest read (a plug-in's, a test's)
        return ok, None
    moving = ok & ~np.asarray(arrays["settled"], bool)
    return ok & ~moving, int(moving.sum())


def stops(sel, k: int, labels: Sequence[np.ndarray], eligible: Sequence[np.ndarray], n: int,
           dcfg: DatasetConfig, max_chunks: int) -> bool:
    """Does generation stop at ``k`` chunks with selection ``sel`` (None: no balanced one yet)?
    At the cap, after ``match_patience``, or once the matching borrows at most ``borrow_fraction``."""
    if sel is None:
        return False
    return (k >= max_chunks or k >= patience_chunks(labels, eligible, n, dcfg.match_patience)
            or sel.borrowed <= dcfg.borrow_fraction * sel.n_negative)


def first_stop(labels, dists, eligible, n: int, seed: int, dcfg: DatasetConfig, max_chunks: int) -> int | None:
    """The fewest of the stored chunks at which a run of this scheme would stop, or None."""
    cat = lambda xs, dt: np.concatenate(xs) if xs else np.zeros(0, dt)
    for k in range(len(labels) + 1):
        lab, ok = labels[:k], eligible[:k]
        sel = select_balanced(cat(lab, bool), cat(dists[:k], float), n, seed, dcfg.distance_bins,
                              eligible=cat(ok, bool), negatives=dcfg.negatives)
        if stops(sel, k, lab, ok, n, dcfg, max_chunks):
            return k
    return None


def patience_chunks(labels: Sequence[np.ndarray], eligible: Sequence[np.ndarray], n: int, patience: float) -> int:
    """``ceil(patience * k1)``, k1 the first chunk count whose eligible rollouts hold a balanced
    selection (a count condition only, so a resumed run stops where an unbroken one does)."""
    pos = np.cumsum([int((l & e).sum()) for l, e in zip(labels, eligible)])
    neg = np.cumsum([int((~l & e).sum()) for l, e in zip(labels, eligible)])
    first = np.flatnonzero((pos >= n // 2) & (neg >= n - n // 2))
    return math.ceil(patience * (int(first[0]) + 1)) if len(first) else 2**62
