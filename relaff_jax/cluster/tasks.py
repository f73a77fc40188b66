"""Pieces of a stage as Dask tasks: in index order with a bounded window, or all at once.

- ``Ordered(client, task, limit, window)``: piece ``k`` is ``fn(*args)`` for ``(fn, args) =
  task(k)``; ``get(k)`` returns its result, keeping pieces ``k .. k + window - 1`` (below
  ``limit``) submitted so the workers stay busy while the driver consumes results in index
  order. ``client=None`` runs ``get(k)`` in this process, one piece at a time (the run
  without a cluster), or, given ``pool`` (a ``concurrent.futures`` executor), ``window``
  pieces at once on its threads. ``finish()`` waits for the pieces still in flight (tasks already
  running on a worker cannot be stopped) and returns their indices, so the caller can discard
  what they wrote; ``cancel()`` drops them.
- ``map_calls(client, calls, on_result)``: every ``(fn, args, kwargs)`` of ``calls`` as one
  task, ``on_result(i, result)`` called as tasks complete (any order). Arguments shared by
  several calls (the same numpy array or dict object, e.g. a target pool's states) are
  scattered to the cluster once instead of being pickled into every task.

A worker that dies loses only its running task: Dask reschedules it on another worker
(``distributed.scheduler.allowed-failures`` times), and each task writes its piece atomically,
so a rerun or a retry cannot leave half a piece or a second copy.
"""
from __future__ import annotations

import pickle
import weakref
from typing import Any, Callable, Sequence

import numpy as np
from relaff_jax.cluster.client import nthreads

SCATTER_BYTES = 64 * 1024  # shared arguments at least this large are sent to the cluster once
_LIVE: "weakref.WeakSet[Ordered]" = weakref.WeakSet()  # runners with tasks on a cluster


class Ordered:
    """Tasks ``task(k) -> (fn, args)`` for ``k < limit``, submitted in order, read in order."""

    def __init__(self, client: Any, task: Callable[[int], tuple], limit: int, window: int | None = None,
                 pool: Any = None):
        self.client, self.task, self.limit = client, task, int(limit)
        self.pool = pool if client is None else None
        if client is not None and window is None:
            window = nthreads(client)
        self.window = max(1, int(window or 1))
        self.futures: dict[int, Any] = {}
        if client is not None:
            _LIVE.add(self)

    def get(self, k: int) -> Any:
        """The result of piece ``k`` (raises what the task raised)."""
        if self.client is None and self.pool is None:
            fn, args = self.task(k)
            return fn(*args)
        for j in range(k, min(k + self.window, self.limit)):
            if j not in self.futures:
                fn, args = self.task(j)
                self.futures[j] = self.pool.submit(fn, *args) if self.pool is not None else \
                    self.client.submit(fn, *args, pure=False, key=f"{getattr(fn, '__name__', 'task')}-{j}-{id(self)}")
        fut = self.futures.pop(k)
        return fut.result()

    def finish(self) -> list[int]:
        """Wait for the pieces still in flight (their errors ignored); their indices."""
        if not self.futures:
            return []
        if self.pool is not None:
            from concurrent.futures import wait
        else:
            from distributed import wait

        wait(list(self.futures.values()))
        done = sorted(self.futures)
        self.futures.clear()
        return done

    def cancel(self) -> None:
        if self.futures and self.client is not None:
            self.client.cancel(list(self.futures.values()))
        for fut in self.futures.values() if self.pool is not None else ():
            fut.cancel()  # a piece already running on a thread finishes; its result is dropped
        self.futures.clear()


def cancel_all(client: Any) -> None:
    """Cancel the queued tasks of every ``Ordered`` runner on ``client`` (from any thread):
    their drivers' ``get`` then raises ``CancelledError`` and they unwind."""
    for runner in list(_LIVE):
        if runner.client is client:
            try:
                client.cancel(list(runner.futures.values()))
            except RuntimeError:  # its dict changed under us: the owner is busy, try once more
                client.cancel(list(runner.futures.values()))


def _size(obj: Any) -> int:
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    try:
        return len(pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))
    except Exception:  # noqa: BLE001 - cloudpickle will deal with it per task
        return 0


def _shared(client: Any, calls: Sequence[tuple]) -> dict[int, Any]:
    """Futures of the arguments (by identity) used by several calls and large enough."""
    uses: dict[int, list] = {}
    for _, args, kwargs in calls:
        for a in list(args) + list(kwargs.values()):
            if isinstance(a, (np.ndarray, dict, list, tuple)):
                uses.setdefault(id(a), [a, 0])[1] += 1
    out = {}
    for i, (obj, n) in uses.items():
        if n >= 2 and _size(obj) >= SCATTER_BYTES:
            out[i] = client.scatter([obj], broadcast=False, hash=False)[0]  # the object as one piece
    return out


def _call(fn: Callable, kwargs: dict, *args: Any) -> Any:
    return fn(*args, **kwargs)


def map_calls(client: Any, calls: Sequence[tuple], on_result: Callable[[int, Any], None]) -> None:
    """Run ``calls`` (``(fn, args, kwargs)``) as tasks; ``on_result(i, r)`` as each completes."""
    from distributed import as_completed

    shared = _shared(client, calls)

    def sub(a):
        return shared.get(id(a), a)

    futures = {}
    for i, (fn, args, kwargs) in enumerate(calls):
        f = client.submit(_call, fn, {k: sub(v) for k, v in kwargs.items()}, *[sub(a) for a in args], pure=False,
                          key=f"{getattr(fn, '__name__', 'call')}-{i}-{id(futures)}")
        futures[f] = i
    try:
        for fut, result in as_completed(list(futures), with_results=True):
            on_result(futures[fut], result)
    except BaseException:
        client.cancel(list(futures))
        raise
