"""The cluster a block of code runs on, without passing it through every signature.

``with active(client): ...`` makes ``current()`` return ``client`` inside the block (a context
variable, so threads and nested blocks each see their own); ``None`` outside means "this
machine, as without ``--cluster``". ``relaff_jax.learn.parallel.run_parallel`` consults it, so
the sweep's callers keep their signatures.
"""
from __future__ import annotations

import contextlib
import contextvars
from typing import Any, Iterator

_CLIENT: contextvars.ContextVar = contextvars.ContextVar("relaff_cluster_client", default=None)


def current() -> Any:
    """The ``distributed.Client`` of the innermost ``active`` block, or None."""
    return _CLIENT.get()


@contextlib.contextmanager
def active(client: Any) -> Iterator[Any]:
    """Run the block with ``current() is client`` (``None`` runs it locally)."""
    token = _CLIENT.set(client)
    try:
        yield client
    finally:
        _CLIENT.reset(token)
