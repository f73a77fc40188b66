"""The one reader of MJX's contact list.

MJX (mujoco 4.0) keeps the contacts of an ``mjx.Data`` in a private field (``d._impl.contact``);
every module reads them through ``contacts(d)``, so a change of MuJoCo's layout is fixed here
only. Takes an ``mjx.Data``; returns its contact struct.
"""
from __future__ import annotations

from typing import Any


def contacts(d: Any) -> Any:
    """The contact struct of one ``mjx.Data`` ``d`` (or of a batch: leading axes kept).

    Fields used by this package: ``dist`` (ncon,), ``frame`` (ncon, 3, 3) (row 0: the
    normal), ``geom`` (ncon, 2) and ``geom1``/``geom2`` (ncon,) geom ids. The slots are a
    fixed, static list of candidate geom pairs (``scenes.contact_masks``).
    """
    return d._impl.contact
