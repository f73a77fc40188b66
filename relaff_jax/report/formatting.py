"""Number formatting shared by the report's tables, findings and document.

``fmt`` (a float as text, ``nan`` for undefined), ``finite`` (a JSON-ready copy with NaN as
None), ``curve_average`` (a bootstrap factor curve ``(S,)`` averaged over the config's bf
interval), ``nanmean`` (mean of the finite values) and ``SHORT`` (short action names).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from relaff_jax.learn import average_bf

SHORT = {"unobstruct": "unob"}


def fmt(x: float, nd: int = 3) -> str:
    return "nan" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def curve_average(curve: np.ndarray, sizes: Sequence[int], cfg: Any) -> float:
    """Average of a bootstrap factor curve over ``cfg.bf_sizes`` (paper V-C)."""
    return float(average_bf(np.asarray(curve), sizes, *cfg.bf_sizes))


def nanmean(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.mean(x[np.isfinite(x)])) if np.any(np.isfinite(x)) else float("nan")


def finite(obj):
    """JSON has no NaN: turn non-finite floats into None."""
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
