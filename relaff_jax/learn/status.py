"""Is an experiment folder finished, and was it made from these datasets and settings?

``experiment_status`` reads the folder's ``experiment.json`` (written by the sweep) and
answers with a state in absent / partial / complete / stale / corrupt and a reason;
``sweep_progress`` counts the blocks written, weighted by each space's forests; so a driver
(``relaff reproduce``) never reads the experiment's files itself.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from relaff_jax import io as rio
from relaff_jax.config.experiment import result_differences

from relaff_jax.learn import folder as L
from relaff_jax.learn.folder import is_complete, META  # noqa: F401 (re-exported)
from relaff_jax.learn.datasets import fingerprint
from relaff_jax.learn import forests_per_space
from relaff_jax.learn.states import state_width


def experiment_status(out: str | os.PathLike, datasets: Mapping[str, Mapping[str, Any]], cfg: Any, seed: int,
                      actions: Sequence[str], spaces: Sequence[str], *,
                      fingerprints: Mapping[str, Mapping[str, str]] | None = None) -> tuple[str, str]:
    """``(state, why)`` of the experiment folder ``out`` for ``datasets`` (name -> loaded
    dataset with features), ``cfg`` (``ExperimentConfig``), ``seed``, ``actions``, ``spaces``.
    ``fingerprints``: ``fingerprint(datasets, spaces)`` already known (then ``datasets`` is
    not read and may be None)."""
    out = Path(out)
    if not (out / META).exists():
        return ("partial", "sweep started, no experiment.json yet") if out.exists() else ("absent", "no folder")
    try:
        meta = rio.read_json(out / META)
    except ValueError as e:
        return "corrupt", str(e)
    changed = result_differences(meta.get("config"), cfg)
    if changed:
        return "stale", f"made with other experiment settings ({', '.join(changed[:4])}{', ...' if len(changed) > 4 else ''})"
    if meta.get("seed") != seed:
        return "stale", f"made with seed {meta.get('seed')}, not {seed}"
    if meta.get("actions") != list(actions):
        return "stale", f"made for actions {meta.get('actions')}, not {list(actions)}"
    now = rio.jsonable(fingerprint(datasets, spaces) if fingerprints is None else fingerprints)
    stored = meta.get("fingerprint", {})
    changed = [s for s in spaces if s in stored and stored[s] != now[s]]
    if changed:
        return "stale", f"the datasets changed since the {', '.join(changed)} sweep"
    if is_complete(out, spaces):
        return "complete", f"{', '.join(spaces)} sweeps finished"
    return "partial", "resumable: some sweep blocks are missing"


def forest_cost_ms(n: int, width: int) -> float:
    """Model of one forest's fit + predict, in ms, at n training samples of ``width`` columns
    (the fast engine on the project's 2 cores, loaded, 2026-12-03: 3.7 / 5.5 / 14 ms at
    n = 2 / 25 / 100 with 18 columns, 3.8 / 7.9 / 39 ms with 300). Only its shape matters: it
    weighs the blocks of a progress fraction so that the ETA does not rise when the costly
    RHF forests and large n come after the cheap ones."""
    return 3.6 + 0.1 * n + (width / 300.0) * 0.0025 * n * n


def sweep_progress(out: str | os.PathLike, cfg: Any, n_actions: int, spaces: Sequence[str]) -> float:
    """Fraction of an experiment's sweeps done, weighted by cost: per space 1 when
    ``results.npz`` exists, else 0.1 for the preparation (source predictors, correlations) and
    0.9 x the blocks written, each block weighted by its sizes' ``forest_cost_ms``; spaces
    weighted by their number of forests (``forests_per_space``) times their mean forest cost."""
    out = Path(out)
    sizes = list(cfg.sizes)  # the sweep's own chunking (sweep.run_space)
    chunks = [sizes[i:i + cfg.sizes_per_block] for i in range(0, len(sizes), cfg.sizes_per_block)]
    done = total = 0.0
    for s in spaces:
        width = state_width(s, cfg.state)
        chunk_cost = [sum(forest_cost_ms(n, width) for n in c) for c in chunks]
        w = forests_per_space(cfg, n_actions, s) * sum(chunk_cost) / len(sizes)
        if L.results(out, s).exists():
            frac = 1.0
        else:
            got = 0.0
            for f in L.block_files(out, s):
                ci = L.block_chunk(f)
                got += chunk_cost[ci] if ci is not None and ci < len(chunks) else 0.0
            frac = 0.1 * L.prep(out, s).exists() + 0.9 * got / (cfg.reps(s) * n_actions * sum(chunk_cost))
        done, total = done + w * frac, total + w
    return done / total if total else 0.0
