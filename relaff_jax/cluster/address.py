"""Cluster addresses as ``--cluster`` takes them.

Takes a string; gives an ``Address``: ``local:N`` (start a ``LocalCluster`` of N spawned worker
processes, one thread each, on this machine) or ``tcp://HOST:PORT`` / ``tls://HOST:PORT`` (join
the Dask scheduler listening there). Anything else is a ``UserError`` naming the problem.
"""
from __future__ import annotations

import dataclasses
import re

from relaff_jax.errors import UserError

_LOCAL = re.compile(r"^local:(\d+)$")
_REMOTE = re.compile(r"^(tcp|tls)://([^\s:/]+|\[[0-9a-fA-F:]+\]):(\d+)/?$")
MAX_LOCAL = 256


@dataclasses.dataclass(frozen=True)
class Address:
    """A parsed cluster address: ``kind`` is ``"local"`` (``workers`` processes) or ``"remote"``
    (``url`` of a scheduler)."""

    kind: str
    workers: int = 0
    url: str = ""

    def __str__(self) -> str:
        return f"local:{self.workers}" if self.kind == "local" else self.url


def parse_address(text: str) -> Address:
    """``local:N`` (1 <= N <= 256) or ``tcp://host:port`` (``tls://`` too); else ``UserError``."""
    if not isinstance(text, str):
        raise UserError(f"--cluster takes a string, got {text!r}")
    s = text.strip()
    m = _LOCAL.match(s)
    if m:
        n = int(m.group(1))
        if not 1 <= n <= MAX_LOCAL:
            raise UserError(f"--cluster {text}: local:N needs 1 <= N <= {MAX_LOCAL} worker processes")
        return Address("local", workers=n)
    m = _REMOTE.match(s)
    if m:
        port = int(m.group(3))
        if not 1 <= port <= 65535:
            raise UserError(f"--cluster {text}: port {port} is outside 1-65535")
        return Address("remote", url=f"{m.group(1)}://{m.group(2)}:{port}")
    raise UserError(f"--cluster {text!r}: expected local:N (N worker processes on this machine) or "
                    "tcp://HOST:PORT (a running Dask scheduler)")
