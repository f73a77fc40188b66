"""The experiment folder's layout, named once (``relaff experiment --out``, ``DIR/results``)::

    OUT/experiment.json            protocol, seed, actions, spaces, data fingerprints
    OUT/SPACE/prep.npz             source predictors, categories, correlations (``prep.py``)
    OUT/SPACE/blocks/T_rRRR_cCC.npz  one sweep block: target T, repetition R, size chunk C
    OUT/SPACE/results.npz          the finished space (``results.py``)
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

from relaff_jax import io as rio
from relaff_jax.config.experiment import result_differences
from relaff_jax.constants import SPACES

META = "experiment.json"
RESULTS = "results.npz"
PREP = "prep.npz"
BLOCKS = "blocks"


def meta(out: str | os.PathLike) -> Path:
    return Path(out) / META


def space_dir(out: str | os.PathLike, space: str) -> Path:
    return Path(out) / space


def results(out: str | os.PathLike, space: str) -> Path:
    return space_dir(out, space) / RESULTS


def prep(out: str | os.PathLike, space: str) -> Path:
    return space_dir(out, space) / PREP


def blocks(out: str | os.PathLike, space: str) -> Path:
    return space_dir(out, space) / BLOCKS


def block(sdir: str | os.PathLike, target: str, rep: int, chunk: int) -> Path:
    """One block's file under a space folder ``sdir``."""
    return Path(sdir) / BLOCKS / f"{target}_r{rep:03d}_c{chunk:02d}.npz"


def block_files(out: str | os.PathLike, space: str) -> list[Path]:
    """The block files a space's sweep has written so far (none if it has not begun)."""
    d = blocks(out, space)
    return list(d.glob("*.npz")) if d.is_dir() else []


def block_chunk(path: str | os.PathLike) -> int | None:
    """The size-chunk index of a block file's name (None if the name is not a block's)."""
    ci = Path(path).stem.rsplit("_c", 1)[-1]
    return int(ci) if ci.isdigit() else None


def meta_differences(old: dict, now: dict, cfg) -> list[str]:
    """What makes the experiment recorded in ``old`` (a stored ``experiment.json``) another one
    than ``now`` (the record a run of ``cfg``, an ``ExperimentConfig``, would write): ``format``,
    ``seed``, ``actions``, ``plugins``, ``action_specs``, ``config.KEY`` for each result key
    (``config.experiment.result_differences``) and ``SPACE data`` for each of ``now``'s spaces
    whose data fingerprint differs. The sweep's resume check and ``--reuse``'s share it."""
    now = rio.jsonable(now)
    diff = [k for k in ("format", "seed", "actions") if old.get(k) != now[k]]
    diff += ["plugins"] if old.get("plugins", {}) != now["plugins"] else []
    diff += ["action_specs"] if old.get("action_specs", {}) != now.get("action_specs", {}) else []
    diff += [f"config.{k}" for k in result_differences(old.get("config"), cfg)]
    diff += [f"{s} data" for s in now["spaces"] if s in old.get("fingerprint", {})
             and old["fingerprint"][s] != now["fingerprint"][s]]
    return diff


def is_complete(out: str | os.PathLike, spaces: Sequence[str] = SPACES) -> bool:
    """Whether ``out`` holds finished results for every one of ``spaces``."""
    out = Path(out)
    if not meta(out).exists():
        return False
    try:
        done = rio.read_json(meta(out))["spaces"]
    except (ValueError, KeyError):
        return False
    return all(s in done and results(out, s).exists() for s in spaces)
