"""A function built where it runs: how compiled programs reach cluster workers.

``Remote(factory, *args, pick=None, **kwargs)`` is a small picklable callable standing for
``factory(*args, **kwargs)`` (or its item ``pick``, e.g. the ``rollout_fn`` of a
``(rollout_fn, config_dict, names)`` factory). Only the factory and its arguments travel to a
worker (a few kB: module-level functions by reference, frozen configs by value); the first
call in a process builds the function and keeps it in a per-process cache keyed by the
recipe's hash, so each worker builds (and JAX compiles) once and reuses it for every task it
runs. Without a cluster the driver itself builds it once, as before.
"""
from __future__ import annotations

import collections
import hashlib
from typing import Any, Callable

from relaff_jax.errors import UserError

_BUILT: "collections.OrderedDict[str, Callable]" = collections.OrderedDict()
CACHE_SIZE = 16  # recipes kept per process (a run: one rollout function per action + one feature function)


class Remote:
    """``factory(*args, **kwargs)[pick]`` built lazily, once per process."""

    def __init__(self, factory: Callable, *args: Any, pick: int | str | None = None, **kwargs: Any):
        if not callable(factory):
            raise UserError(f"Remote needs a callable factory, got {factory!r}")
        import cloudpickle

        self.factory, self.args, self.kwargs, self.pick = factory, args, kwargs, pick
        try:
            blob = cloudpickle.dumps((factory, args, kwargs, pick))
        except Exception as e:  # noqa: BLE001 - any pickling failure means it cannot be shipped
            raise UserError(f"cannot send {getattr(factory, '__name__', factory)!r} to cluster workers: its "
                            f"factory or arguments are not picklable ({type(e).__name__}: {e})") from e
        self.key = hashlib.sha256(blob).hexdigest()

    def build(self) -> Callable:
        """The built function (from this process's cache after the first call)."""
        fn = _BUILT.get(self.key)
        if fn is None:
            out = self.factory(*self.args, **self.kwargs)
            fn = out if self.pick is None else out[self.pick]
            _BUILT[self.key] = fn
            while len(_BUILT) > CACHE_SIZE:
                _BUILT.popitem(last=False)
        else:
            _BUILT.move_to_end(self.key)
        return fn

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.build()(*args, **kwargs)

    def __repr__(self) -> str:
        return f"Remote({getattr(self.factory, '__name__', self.factory)!r}, key={self.key[:12]})"
