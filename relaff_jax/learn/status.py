"""Is an experiment folder finished, and was it made from these datasets and settings?

``experiment_status`` reads the folder's ``experiment.json`` (written by the sweep) and
answers with a state in absent / partial / complete / stale / corrupt and a reason;
``sweep_progress`` counts the blocks written, weighted by each space's forests; so a driver
(``relaff reproduce``) never reads the experiment's files itself.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from relaff_jax import io as rio
from relaff_jax.config import to_dict

META = "experiment.json"


def experiment_status(out: str | os.PathLike, datasets: Mapping[str, Mapping[str, Any]], cfg: Any, seed: int,
                      actions: Sequence[str], spaces: Sequence[str]) -> tuple[str, str]:
    """``(state, why)`` of the experiment folder ``out`` for ``datasets`` (name -> loaded
    dataset with features), ``cfg`` (``ExperimentConfig``), ``seed``, ``actions``, ``spaces``."""
    from relaff_jax.learn import fingerprint, is_complete

    out = Path(out)
    if not (out / META).exists():
        return ("partial", "sweep started, no experiment.json yet") if out.exists() else ("absent", "no folder")
    try:
        meta = rio.read_json(out / META)
    except ValueError as e:
        return "corrupt", str(e)
    if meta.get("config") != rio.jsonable(to_dict(cfg)):
        return "stale", "made with other experiment settings"
    if meta.get("seed") != seed:
        return "stale", f"made with seed {meta.get('seed')}, not {seed}"
    if meta.get("actions") != list(actions):
        return "stale", f"made for actions {meta.get('actions')}, not {list(actions)}"
    now = rio.jsonable(fingerprint(datasets, spaces))
    stored = meta.get("fingerprint", {})
    changed = [s for s in spaces if s in stored and stored[s] != now[s]]
    if changed:
        return "stale", f"the datasets changed since the {', '.join(changed)} sweep"
    if is_complete(out, spaces):
        return "complete", f"{', '.join(spaces)} sweeps finished"
    return "partial", "resumable: some sweep blocks are missing"


def sweep_progress(out: str | os.PathLike, cfg: Any, n_actions: int, spaces: Sequence[str]) -> float:
    """Fraction of an experiment's sweeps done: per space 1 when ``results.npz`` exists, else
    0.1 for the preparation (source predictors, correlations) and 0.9 x the blocks written;
    spaces weighted by their number of forests (``forests_per_space``)."""
    from relaff_jax.learn import forests_per_space

    out = Path(out)
    n_chunks = math.ceil(len(cfg.sizes) / cfg.sizes_per_block)
    done = total = 0.0
    for s in spaces:
        w = forests_per_space(cfg, n_actions, s)
        blocks = out / s / "blocks"
        n_blocks = len(list(blocks.glob("*.npz"))) if blocks.is_dir() else 0
        frac = 1.0 if (out / s / "results.npz").exists() else \
            0.1 * (out / s / "prep.npz").exists() + 0.9 * n_blocks / (cfg.reps(s) * n_actions * n_chunks)
        done, total = done + w * frac, total + w
    return done / total if total else 0.0
