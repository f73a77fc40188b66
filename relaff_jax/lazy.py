"""Lazy package attributes (PEP 562): a package's heavy names load on first use.

``sim``, ``learn`` and ``perception`` import their configs at once (no JAX, MJX or
scikit-learn) and everything else when it is first read, so that the command line checks
``--set`` in well under a second.
"""
from __future__ import annotations

import importlib
from typing import Any, Callable, Mapping


def lazy_attributes(package: str, names: Mapping[str, str], namespace: dict) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for ``package``: ``names`` maps an attribute to the submodule
    that defines it; a name read once is bound in ``namespace`` (the package's globals)."""

    def __getattr__(name: str) -> Any:
        if name in names:
            value = getattr(importlib.import_module(f"{package}.{names[name]}"), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(names))

    return __getattr__, __dir__
