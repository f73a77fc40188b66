"""Run independent forest jobs over worker processes, in order, with a progress bar.

Takes ``calls``: ``[(function, args, kwargs)]`` of picklable module-level functions; gives
their results in call order. ``jobs == 1`` runs in this process (what tests monkeypatch);
otherwise joblib's process pool, results collected as they finish. With ``client`` (a
``distributed.Client``) every call is a task on that Dask cluster instead
(``cluster.map_calls``; ``jobs`` is then ignored), with the same results and progress. The
bar counts ``weights`` (forest fits per call) from ``initial`` (fits already on disk) to
``total``.
"""
from __future__ import annotations

from typing import Any


def run_parallel(calls: list, jobs: int, progress: bool, total: int, desc: str, unit: str, weights=None, initial: int = 0,
                 client: Any = None) -> list:
    """Run joblib ``calls`` over ``jobs`` processes (or ``client``'s cluster), in order, with a progress bar."""
    from tqdm import tqdm

    weights = [1] * len(calls) if weights is None else weights
    bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, disable=not progress, smoothing=0, dynamic_ncols=True)
    results: list = [None] * len(calls)

    def done(i, r):
        results[i] = r
        bar.update(weights[i])

    try:
        if client is not None and calls:
            from relaff_jax.cluster.tasks import map_calls

            map_calls(client, calls, done)
        elif jobs == 1:
            for i, c in enumerate(calls):
                fn, args, kwargs = c
                done(i, fn(*args, **kwargs))
        else:
            from joblib import Parallel

            indexed = [(_indexed, (i, c), {}) for i, c in enumerate(calls)]
            for i, r in Parallel(n_jobs=jobs, return_as="generator_unordered")(indexed):
                done(i, r)
    finally:
        bar.close()
    return results


def _indexed(i: int, call):
    fn, args, kwargs = call
    return i, fn(*args, **kwargs)
