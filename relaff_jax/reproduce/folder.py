"""The run folder of ``relaff reproduce`` (its layout: ``stages.protocol.Paths``) and the run log.

::

    DIR/run.json          run log: preset, the whole resolved config tree, seeds, package
                          versions, machine (CPU, BLAS kernels), and per invocation the status
                          and wall time of every stage, and the machine when it is another
    DIR/data/<action>/    the balanced datasets with their PCA/RHF features (relaff_jax.data)
    DIR/results/          the experiment folder (relaff_jax.learn), both state spaces
    DIR/report/           report.md, report.html, Table II, figures, examples (relaff_jax.report)

A folder holds one study: opening it with another preset, config or seed is refused.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from relaff_jax import io as rio
from relaff_jax.config import differences, RunConfig, streams, to_dict
from relaff_jax.sim.actions.registry import names
from relaff_jax.errors import UserError
from relaff_jax.provenance import derive_seed, machine, versions
from relaff_jax.stages.protocol import RUN_LOG, Paths, ReproduceError
from relaff_jax.config.real import SHADOWED
from relaff_jax.config.tree import shadow_matches
from relaff_jax.config.experiment import SPEED_ONLY

FORMAT = "relaff_jax.reproduce"
FORMAT_VERSION = 2  # 2: the config is the whole RunConfig tree


def seeds(seed: int) -> dict[str, Any]:
    """The seeds of every stage, derived from the run seed (independent streams)."""
    return {
        "run": int(seed),
        "datasets": {a: derive_seed(seed, streams.RUN_FOLDER, 1, i) for i, a in enumerate(names())},  # ACTIONS', then a user's
        "features": derive_seed(seed, streams.RUN_FOLDER, 2),
        "experiment": int(seed),
    }


def now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


def _added_at_default(key: str, stored: Any, wanted: Any) -> bool:
    """A config key absent from a stored run log and requested at the code's default."""
    if stored != "<absent>" or not key.startswith("config."):
        return False

    node: Any = json.loads(json.dumps(to_dict(RunConfig()), default=rio.json_default))
    for part in key.split(".")[1:]:
        if not isinstance(node, dict) or part not in node:
            return False
        node = node[part]
    return node == wanted


def _shadow_removed(key: str, stored: Any, wanted: Any, want: dict) -> bool:
    """A ``real.experiment`` key a stored run log has and the tree no longer has (it is taken
    from ``experiment`` now, ``config.real.SHADOWED``), stored at the value the tree gives."""
    name = key.removeprefix("config.real.experiment.")
    return wanted == "<absent>" and name in SHADOWED and key == f"config.real.experiment.{name}" \
        and shadow_matches(name, stored, want.get("config", {}))


def _speed_only(key: str) -> bool:
    """A run log key of a setting that changes no result (``config.experiment.SPEED_ONLY``)."""
    return key.startswith("config.experiment.") and key.removeprefix("config.experiment.") in SPEED_ONLY


def damaged_log_hint(root: Path) -> str:
    return (f"every stage's own output is untouched: rebuild the log with `relaff reproduce --out {root} "
            "--rebuild-log` and the --preset, --seed and --set options the run was made with (stages made "
            "with other settings then show as stale)")


def open_log(paths: Paths, preset_name: str, cfg: Any, seed: int, rebuild: bool = False) -> dict[str, Any]:
    """Read or create the run log; a DIR of another preset, config or seed is refused.
    ``rebuild``: a damaged run log is set aside (``run.json.damaged``) and a new one written for
    the requested settings; the stages then find their own outputs and skip what is complete."""
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
            if not isinstance(log, dict) or log.get("format") != FORMAT:
                raise ValueError("not a relaff reproduce run log")
        except (OSError, ValueError) as e:
            if not rebuild:
                raise ReproduceError(f"{paths.log} is damaged ({e}); {damaged_log_hint(root)}") from e
            os.replace(paths.log, paths.log.with_name(RUN_LOG + ".damaged"))
            log = None
        if log is not None:
            if rebuild:
                raise ReproduceError(f"{paths.log} is intact; --rebuild-log is only for a damaged run log")
            return _check_log(log, want, root)
    elif rebuild:
        if not root.is_dir():
            raise ReproduceError(f"{root} does not exist: nothing to rebuild")
    elif root.exists() and any(not p.name.startswith(".") for p in root.iterdir()):
        raise ReproduceError(f"{root} exists, is not empty and holds no {RUN_LOG}: not a relaff reproduce folder")
    os.makedirs(root, exist_ok=True)
    log = {"format": FORMAT, "format_version": FORMAT_VERSION, "created": now(), **want,
           "seeds": seeds(seed), "versions": versions(), "machine": machine(), "runs": [], "timings": {}}
    if rebuild:
        log["rebuilt"] = now()
    rio.atomic_write_json(paths.log, log)
    return log


def _check_log(log: dict, want: dict, root: Path) -> dict:
    if log.get("format_version") != FORMAT_VERSION:
        raise ReproduceError(f"{root} was made by another version of relaff reproduce (run log format "
                             f"{log.get('format_version')}, this one writes {FORMAT_VERSION}); use a new --out")
    stored = {k: log.get(k, "<absent>") for k in want}
    diff = differences(stored, want)
    # a log written before the tree had a seed: its seed is the log's own
    added = [d for d in diff if _added_at_default(*d) or (d[0] == "config.seed" and d[1] == "<absent>"
                                                          and d[2] == log.get("seed"))]
    removed = [d for d in diff if _shadow_removed(*d, want)]  # now taken from another node
    speed = [d for d in diff if _speed_only(d[0])]
    # the tree's seed is the log's own seed, compared as such
    diff = [d for d in diff if d not in added and d not in speed and d not in removed
            and not (d[0] == "config.seed" and "seed" in want)]
    if (added or speed or removed) and not diff:
        # settings that did not exist when the run began, requested at their defaults (most
        # keep the old behaviour; dataset.unsettled changes a selection, and the dataset then
        # selects again from its stored rollouts, the later stages following), and settings
        # that change no result (the forest engine): the
        # same run; the log records the requested values from now on, and when a speed setting changed
        log["config"] = want["config"]
        log.setdefault("added_settings", []).extend(k.removeprefix("config.") for k, _, _ in added)
        if removed:
            log.setdefault("removed_settings", []).extend(k.removeprefix("config.") for k, _, _ in removed)
        log.setdefault("speed_settings_changed", []).extend(
            {"at": now(), "key": k.removeprefix("config."), "was": a, "now": b} for k, a, b in speed)
        if not log["speed_settings_changed"]:
            del log["speed_settings_changed"]
        if not log["added_settings"]:
            del log["added_settings"]
        rio.atomic_write_json(root / RUN_LOG, log)
    if diff:
        what = sorted({key.split(".")[0] for key, _, _ in diff})
        shown = "; ".join(f"{key.removeprefix('config.')}: stored {json.dumps(a)[:60]}, requested {json.dumps(b)[:60]}"
                          for key, a, b in diff[:8])
        more = f"; and {len(diff) - 8} more" if len(diff) > 8 else ""
        raise ReproduceError(f"{root} holds a run with another {', '.join(what)} ({len(diff)} key(s) differ: "
                             f"{shown}{more}); use a new --out (or the same options) to continue")
    return log
