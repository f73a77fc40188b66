"""The base of every config node: a frozen dataclass checked once, when it is built."""
from __future__ import annotations

from typing import Any, ClassVar, Mapping

from relaff_jax.config import constraints


class Node:
    """Mixin of the tree's frozen dataclasses: ``_path`` is the node's dotted place in the tree
    (for messages), ``_constraints`` its declared checks (``constraints``); ``__post_init__``
    runs the one generic checker. Nested nodes check themselves when they are built."""

    _path: ClassVar[str] = ""
    _constraints: ClassVar[Mapping[Any, Any]] = {}

    def __post_init__(self) -> None:
        constraints.check_node(self)  # looked up at call time, so a test can count the calls
