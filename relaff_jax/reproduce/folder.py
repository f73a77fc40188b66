"""The run folder of ``relaff reproduce``: where each stage writes, and the run log.

::

    DIR/run.json          run log: preset, the whole resolved config tree, seeds, package
                          versions, machine, and per invocation the status and wall time of
                          every stage
    DIR/data/<action>/    the balanced datasets with their PCA/RHF features (relaff_jax.data)
    DIR/results/          the experiment folder (relaff_jax.learn), both state spaces
    DIR/report/           report.md, report.html, Table II, figures, examples (relaff_jax.report)

A folder holds one study: opening it with another preset, config or seed is refused.
"""
from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Any

from relaff_jax import io as rio
from relaff_jax.config import to_dict
from relaff_jax.constants import ACTIONS
from relaff_jax.errors import UserError
from relaff_jax.provenance import derive_seed, machine, versions

FORMAT = "relaff_jax.reproduce"
FORMAT_VERSION = 2  # 2: the config is the whole RunConfig tree
RUN_LOG = "run.json"


class ReproduceError(UserError):
    """Bad input, or a DIR that cannot be used for this run."""


@dataclasses.dataclass(frozen=True)
class Paths:
    root: Path

    @property
    def log(self) -> Path:
        return self.root / RUN_LOG

    @property
    def data(self) -> Path:
        return self.root / "data"

    @property
    def results(self) -> Path:
        return self.root / "results"

    @property
    def report(self) -> Path:
        return self.root / "report"

    def dataset(self, action: str) -> Path:
        return self.data / action


def seeds(seed: int) -> dict[str, Any]:
    """The seeds of every stage, derived from the run seed (independent streams)."""
    return {
        "run": int(seed),
        "datasets": {a: derive_seed(seed, 0x5EED, 1, i) for i, a in enumerate(ACTIONS)},
        "features": derive_seed(seed, 0x5EED, 2),
        "experiment": int(seed),
    }


def now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


def open_log(paths: Paths, preset_name: str, cfg: Any, seed: int) -> dict[str, Any]:
    """Read or create the run log; a DIR of another preset, config or seed is refused."""
    root = paths.root
    try:
        rio.check_writable_dir(root)
    except UserError as e:
        raise ReproduceError(str(e)) from e
    want = {"preset": preset_name, "seed": int(seed),
            "config": json.loads(json.dumps(to_dict(cfg), default=rio.json_default))}
    if paths.log.exists():
        try:
            log = rio.read_json(paths.log)
        except (OSError, ValueError) as e:
            raise ReproduceError(f"{paths.log} is corrupt ({e}); use a new --out") from e
        if not isinstance(log, dict) or log.get("format") != FORMAT:
            raise ReproduceError(f"{paths.log} is not a relaff reproduce run log")
        if log.get("format_version") != FORMAT_VERSION:
            raise ReproduceError(f"{root} was made by another version of relaff reproduce (run log format "
                                 f"{log.get('format_version')}, this one writes {FORMAT_VERSION}); use a new --out")
        diff = [k for k in ("preset", "seed", "config") if log.get(k) != want[k]]
        if diff:
            detail = "; ".join(f"{k}: stored {json.dumps(log.get(k))[:80]}, requested {json.dumps(want[k])[:80]}"
                               for k in diff)
            raise ReproduceError(f"{root} holds a run with another {', '.join(diff)} ({detail}); "
                                 "use a new --out (or the same options) to continue")
        return log
    if root.exists() and any(not p.name.startswith(".") for p in root.iterdir()):
        raise ReproduceError(f"{root} exists, is not empty and holds no {RUN_LOG}: not a relaff reproduce folder")
    os.makedirs(root, exist_ok=True)
    log = {"format": FORMAT, "format_version": FORMAT_VERSION, "created": now(), **want,
           "seeds": seeds(seed), "versions": versions(), "machine": machine(), "runs": [], "timings": {}}
    rio.atomic_write_json(paths.log, log)
    return log
