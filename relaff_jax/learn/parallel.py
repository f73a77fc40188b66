"""Run independent forest jobs over worker processes, in order, with a progress bar.

Takes ``calls``: ``[(function, args, kwargs)]`` of picklable module-level functions; gives
their results in call order. ``jobs == 1`` runs in this process (what tests monkeypatch);
otherwise joblib's process pool, results collected as they finish. The bar counts
``weights`` (forest fits per call) from ``initial`` (fits already on disk) to ``total``.
"""
from __future__ import annotations


def run_parallel(calls: list, jobs: int, progress: bool, total: int, desc: str, unit: str, weights=None, initial: int = 0) -> list:
    """Run joblib ``calls`` over ``jobs`` processes, in order, with a progress bar."""
    from joblib import Parallel
    from tqdm import tqdm

    weights = [1] * len(calls) if weights is None else weights
    bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, disable=not progress, smoothing=0, dynamic_ncols=True)
    results: list = [None] * len(calls)
    try:
        if jobs == 1:
            for i, c in enumerate(calls):
                fn, args, kwargs = c
                results[i] = fn(*args, **kwargs)
                bar.update(weights[i])
        else:
            indexed = [(_indexed, (i, c), {}) for i, c in enumerate(calls)]
            for i, r in Parallel(n_jobs=jobs, return_as="generator_unordered")(indexed):
                results[i] = r
                bar.update(weights[i])
    finally:
        bar.close()
    return results


def _indexed(i: int, call):
    fn, args, kwargs = call
    return i, fn(*args, **kwargs)
