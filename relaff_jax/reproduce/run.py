"""One command from nothing to the paper's results: ``relaff reproduce``.

Takes a preset (``tiny``, ``quick``, ``paper``), a seed and an output folder ``DIR``; runs the
four stages of the study in order and leaves::

    DIR/run.json          run log: preset, config, seeds, package versions, machine, and per
                          run and stage the status ("ran" / "skipped") and wall time
    DIR/data/<action>/    the nine balanced datasets (relaff_jax.dataset) with PCA/RHF features
    DIR/results/          the experiment folder (relaff_jax.experiment), both state spaces
    DIR/report/           report.md, report.html (self-contained), Table II, figures, examples

Stages: ``generate`` (every action's rollouts, ``dataset.generate_dataset`` with
``actions.make_rollout_fn``) -> ``features`` (``dataset.add_features`` with the perception
glue of ``features.py``) -> ``experiment`` (``experiment.run_experiment``, PCA and RHF) ->
``report`` (``report.write_full_report``). A stage is skipped when its output in ``DIR`` is
complete and valid, as the stage modules themselves define it (a finished dataset whose
chunks and selection verify; feature chunks of the same perception config; results whose
config, seed and data fingerprint match; a report stamped with the hash of the results and
datasets it was made from). Every stage writes atomically and resumes, and every random
quantity is seeded from ``--seed``, so a killed run, rerun, ends with the same results as an
uninterrupted one. ``--force STAGE`` redoes one stage; later stages follow only if their inputs
changed.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import importlib
import importlib.metadata
import json
import math
import os
import platform
import shutil
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import ConfigError, from_dict, override, to_dict

from relaff_jax.constants import ACTIONS, SPACES, STAGES  # noqa: F401 (re-exported)
PRESETS = ("tiny", "quick", "paper")
FORMAT = "relaff_jax.reproduce"
FORMAT_VERSION = 1
RUN_LOG = "run.json"
REPORT_STAMP = "report_stamp.json"


class ReproduceError(ValueError):
    """Bad input, or a DIR that cannot be used for this run."""


# ------------------------------------------------------------------------------- config


def _experiment_config():
    from relaff_jax.learn.experiment import ExperimentConfig

    return ExperimentConfig()


@dataclasses.dataclass(frozen=True)
class ReproduceConfig:
    """Everything a run needs besides the seed. Defaults are the ``paper`` preset.

    n_samples: balanced samples per action (paper IV-D: ~10,000).
    rollout_batch: scenes per ``rollout_fn`` call (one compiled program per action and shape).
    max_rollouts, distance_bins, borrow_fraction: ``dataset.DatasetConfig`` of every action.
    feature_batch: scenes per perception call.
    examples_per_action: example scenes drawn per action in the report.
    actions: the actions studied (the paper's nine; a subset of at least two for partial studies).
    spaces: state spaces of the experiment.
    experiment: the learning protocol (``experiment.ExperimentConfig``).
    """

    n_samples: int = 10_000
    rollout_batch: int = 1024
    max_rollouts: int = 200_000
    distance_bins: int = 20
    borrow_fraction: float = 0.01
    feature_batch: int = 32
    examples_per_action: int = 2
    actions: tuple[str, ...] = ACTIONS
    spaces: tuple[str, ...] = SPACES
    experiment: Any = dataclasses.field(default_factory=_experiment_config)


def preset(name: str) -> ReproduceConfig:
    """The three presets.

    ``paper``: the full protocol (10,000 samples per action, every n in 2..100, 50/25
    repetitions, 4000 test samples, the paper's forests): about 30 hours on two cores.
    ``quick``: the README's main job, a small but complete study (all nine actions, both
    spaces, every bootstrapping condition) that finishes in under 15 minutes on two cores (10.4 min
    measured on two idle cores, docs/reproduce.md):
    100 samples per action, n in {2, 4, 10, 25}, 2 repetitions, the paper's forests; the
    learning pools shrink to the data (``ExperimentConfig.shrink_to_data``).
    ``tiny``: for tests: 24 samples per action, n in {2, 4, 10}, 2 repetitions, 8-tree forests.
    """
    from relaff_jax.learn.experiment import preset as exp_preset

    if name == "paper":
        return ReproduceConfig(experiment=exp_preset("paper"))
    if name == "quick":
        exp = override(exp_preset("quick"), {"sizes": (2, 4, 10, 25), "reps_pca": 2, "reps_rhf": 2})
        return ReproduceConfig(n_samples=100, rollout_batch=64, max_rollouts=20_000, distance_bins=10,
                               borrow_fraction=0.05, feature_batch=16, examples_per_action=2, experiment=exp)
    if name == "tiny":
        exp = override(exp_preset("quick"), {"sizes": (2, 4, 10), "reps_pca": 2, "reps_rhf": 2,
                                             "forest.base_trees": 8, "forest.max_trees": 8})
        return ReproduceConfig(n_samples=24, rollout_batch=8, max_rollouts=2_000, distance_bins=4,
                               borrow_fraction=1.0, feature_batch=8, examples_per_action=1, experiment=exp)
    raise ReproduceError(f"unknown preset {name!r}; expected one of {', '.join(PRESETS)}")


def config_from_dict(d: Mapping[str, Any]) -> ReproduceConfig:
    """Rebuild a config from ``to_dict`` output (the run log's ``config``)."""
    from relaff_jax.learn.experiment import ExperimentConfig

    d = dict(d)
    exp = from_dict(ExperimentConfig, d.pop("experiment"))
    return from_dict(ReproduceConfig, dict(d, spaces=tuple(d.get("spaces", SPACES)),
                                           actions=tuple(d.get("actions", ACTIONS)), experiment=exp))


def check_config(cfg: ReproduceConfig, seed: int) -> None:
    """Fail before any simulation if the config cannot give a complete study."""
    from relaff_jax.learn import experiment as E

    def pos_int(name, v, lo=1):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise ReproduceError(f"{name} must be an integer >= {lo}, got {v!r}")

    pos_int("n_samples", cfg.n_samples, 4)
    pos_int("rollout_batch", cfg.rollout_batch)
    pos_int("max_rollouts", cfg.max_rollouts)
    pos_int("distance_bins", cfg.distance_bins)
    pos_int("feature_batch", cfg.feature_batch)
    pos_int("examples_per_action", cfg.examples_per_action, 0)
    if not 0.0 <= float(cfg.borrow_fraction) <= 1.0:
        raise ReproduceError(f"borrow_fraction must be in [0, 1], got {cfg.borrow_fraction}")
    acts = tuple(cfg.actions)
    if len(acts) < 2 or len(set(acts)) != len(acts) or not set(acts) <= set(ACTIONS):
        raise ReproduceError(f"actions must be at least two distinct values of {ACTIONS}, got {cfg.actions}")
    if acts != tuple(a for a in ACTIONS if a in acts):
        raise ReproduceError(f"actions must be in the canonical order {ACTIONS}, got {cfg.actions}")
    spaces = tuple(cfg.spaces)
    if not spaces or len(set(spaces)) != len(spaces) or not set(spaces) <= set(SPACES):
        raise ReproduceError(f"spaces must be distinct values of {SPACES}, got {cfg.spaces}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ReproduceError(f"seed must be an integer in [0, 2**32), got {seed!r}")
    try:
        E.check_config(cfg.experiment)
        for i in range(len(ACTIONS)):  # the learning pools of every action must fit in n_samples
            E.split_pools(cfg.n_samples, i, cfg.experiment, seed)
    except ValueError as e:
        raise ReproduceError(f"the experiment cannot run on {cfg.n_samples} samples per action: {e}") from e


def seeds(seed: int) -> dict[str, Any]:
    """The seeds of every stage, derived from the run seed (independent streams)."""
    def s(*k):
        return int(np.random.SeedSequence([int(x) for x in k]).generate_state(1)[0])

    return {
        "run": int(seed),
        "datasets": {a: s(seed, 0x5EED, 1, i) for i, a in enumerate(ACTIONS)},
        "features": s(seed, 0x5EED, 2),
        "experiment": int(seed),
    }


# ------------------------------------------------------------------------ run folder


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {"python": platform.python_version()}
    for pkg in ("relaff_jax", "jax", "jaxlib", "mujoco", "mujoco-mjx", "numpy", "scikit-learn",
                "orbax-checkpoint", "matplotlib"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def _machine() -> dict[str, Any]:
    return {"platform": platform.platform(), "machine": platform.machine(), "cpus": os.cpu_count()}


@dataclasses.dataclass
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


def _now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


def _open_log(paths: Paths, preset_name: str, cfg: ReproduceConfig, seed: int) -> dict[str, Any]:
    """Read or create the run log; a DIR of another preset, config or seed is refused."""
    root = paths.root
    if root.exists() and not root.is_dir():
        raise ReproduceError(f"{root} exists and is not a directory")
    want = {"preset": preset_name, "seed": int(seed), "config": json.loads(json.dumps(to_dict(cfg), default=rio._json_default))}
    if paths.log.exists():
        try:
            log = rio.read_json(paths.log)
        except (OSError, ValueError) as e:
            raise ReproduceError(f"{paths.log} is corrupt ({e}); use a new --out") from e
        if not isinstance(log, dict) or log.get("format") != FORMAT:
            raise ReproduceError(f"{paths.log} is not a relaff reproduce run log")
        diff = [k for k in ("preset", "seed", "config") if log.get(k) != want[k]]
        if diff:
            detail = "; ".join(f"{k}: stored {json.dumps(log.get(k))[:80]}, requested {json.dumps(want[k])[:80]}"
                               for k in diff)
            raise ReproduceError(f"{root} holds a run with another {', '.join(diff)} ({detail}); "
                                 "use a new --out (or the same options) to continue")
        return log
    if root.exists() and any(not p.name.startswith(".") for p in root.iterdir()):
        raise ReproduceError(f"{root} exists, is not empty and holds no {RUN_LOG}: not a relaff reproduce folder")
    root.mkdir(parents=True, exist_ok=True)
    log = {"format": FORMAT, "format_version": FORMAT_VERSION, "created": _now(), **want,
           "seeds": seeds(seed), "versions": versions(), "machine": _machine(), "runs": [], "timings": {}}
    rio.atomic_write_json(paths.log, log)
    return log


def _remove(path: Path) -> None:
    """Delete a stage's output: renamed first, so a kill leaves only a hidden leftover."""
    if not path.exists():
        return
    tmp = path.parent / f".{path.name}.old.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    os.replace(path, tmp)
    shutil.rmtree(tmp)


def _clean_leftovers(root: Path) -> None:
    for p in root.glob(".*.old.tmp"):
        shutil.rmtree(p, ignore_errors=True)


# --------------------------------------------------------------------- stage helpers


def default_rollout_factory(action: str, batch: int) -> tuple[Callable, dict, Sequence[str] | None]:
    """``(rollout_fn, config_dict, object_names)`` of one action from ``relaff_jax.sim.actions``
    (default ``ActionConfig``; the rollouts carry object names, so no name table)."""
    try:
        actions = importlib.import_module("relaff_jax.sim.actions")
    except ModuleNotFoundError as e:
        if e.name == "relaff_jax.sim.actions":
            raise ReproduceError(
                "the generate stage needs relaff_jax.sim.actions (the arm's nine motor programs that label the "
                "rollouts), which this installation does not have; the datasets cannot be generated") from e
        raise
    cfg = actions.ActionConfig()
    return actions.make_rollout_fn(action, batch, cfg), {"action": action, "action_config": to_dict(cfg)}, None


def default_feature_factory(seed: int) -> tuple[Callable, dict]:
    """``(compute_fn, config_dict)`` of the perception stage, as ``relaff features`` uses it."""
    from relaff_jax.perception.core import from_sim as F
    from relaff_jax.perception import core as pc
    from relaff_jax.sim import world as wd

    cfg = pc.PerceptionConfig()
    return F.make_feature_fn(wd.build_world(), cfg, seed), {"perception": to_dict(cfg), "seed": seed}


def feature_config(seed: int) -> dict:
    """The feature config dict the default factory stores (without building the world)."""
    from relaff_jax.perception import core as pc

    return {"perception": to_dict(pc.PerceptionConfig()), "seed": seed}


def _dataset_complete(path: Path, action: str, n: int, seed: int, batch: int) -> bool:
    """A finished dataset of exactly this request whose chunks and selection verify."""
    from relaff_jax.data import dataset as D

    side = path / D.SIDECAR
    if not side.exists():
        return False
    meta = rio.read_json(side)
    want = {"action": action, "n_samples": n, "seed": seed, "batch": batch}
    diff = {k: (meta.get(k), v) for k, v in want.items() if meta.get(k) != v}
    if diff:
        raise ReproduceError(f"{path} holds another dataset ({', '.join(f'{k} {a} != {b}' for k, (a, b) in diff.items())}); "
                             "remove it or run with --force generate")
    if meta.get("status") != "complete":
        return False
    D.load_dataset(path, features=False)  # verifies every chunk and the selection
    return True


def _features_state(path: Path, batch: int, config: Mapping) -> str:
    """'complete' (features of this config, verified), 'partial' (resumable), 'stale', 'absent'."""
    from relaff_jax.data import dataset as D

    side = path / D.FEATURES_SIDECAR
    if not side.exists():
        return "absent"
    try:
        fmeta = rio.read_json(side)
    except ValueError:
        return "stale"
    stored = json.loads(json.dumps(fmeta.get("config"), default=rio._json_default))
    if fmeta.get("batch") != batch or stored != json.loads(json.dumps(dict(config), default=rio._json_default)):
        return "stale"
    if fmeta.get("status") != "complete":
        return "partial"
    data = D.load_dataset(path)  # verifies the feature chunks
    return "complete" if {"pca", "rhf"} <= set(data) else "stale"


def _hash_files(files: Sequence[Path]) -> str:
    h = hashlib.sha256()
    for f in files:
        h.update(str(f.name).encode())
        h.update(f.read_bytes() if f.exists() else b"<missing>")
    return h.hexdigest()


# ------------------------------------------------------------------------- progress


def _fmt_time(s: float | None) -> str:
    if s is None or not np.isfinite(s):
        return "--:--"
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


# Cost model for the time estimate before a stage has measurable progress: seconds on the
# project's 2-core machine (docs/reproduce.md: where the figures come from).
COST = {
    "sim_compile": 150.0,  # first rollout call: place, settle, plan and simulate programs (all actions)
    "rollouts_per_sample": 2.5,  # rollouts simulated per selected sample (positive rate, matching)
    "rollouts_per_s": 5.0,  # settle + plan + the feasible 3.3 s motor programs (docs/actions.md)
    "feature_compile": 40.0,
    "feature_scenes_per_s": 12.0,
    "cpu_s_per_fit": 0.15,  # a forest of ~100 trees, fit + predict (docs/learning.md)
    "report_fixed": 60.0,
    "report_per_example": 1.5,
}


def estimate_seconds(cfg: ReproduceConfig, jobs: int) -> dict[str, float]:
    """Rough wall time per stage from ``COST`` (used until a stage shows progress)."""
    n, a = cfg.n_samples, len(cfg.actions)
    gen = COST["sim_compile"] + a * n * COST["rollouts_per_sample"] / COST["rollouts_per_s"]
    feat = COST["feature_compile"] + a * n / COST["feature_scenes_per_s"]
    ec = cfg.experiment
    fits = 0
    for s in cfg.spaces:
        fams = ec.conditions(s)
        learners = 1 + ("DB1" in fams) * (a - 1) + ("DBn" in fams) + ("CB1" in fams) * (a - 1) * (a - 2) // 2 \
            + ("CBn" in fams) * len(ec.thresholds)
        fits += learners * len(ec.sizes) * ec.reps(s) * a + a + ("CB1" in fams or "CBn" in fams) * a * (a - 1) // 2
    exp = fits * COST["cpu_s_per_fit"] / max(1, min(jobs, os.cpu_count() or 1))
    rep = COST["report_fixed"] + a * cfg.examples_per_action * COST["report_per_example"]
    return {"generate": gen, "features": feat, "experiment": exp, "report": rep}


class Progress:
    """One progress line for the whole run: stage, its progress, elapsed time and an ETA.

    A stage's progress is read from what it has written to disk (dataset sidecars, feature
    chunks, experiment blocks), by a background thread, so it needs no hooks in the stages
    and is right after a resume. On a terminal the line is redrawn in place; otherwise a line
    is printed when the stage's item changes and every ``every`` seconds.
    """

    def __init__(self, estimates: Mapping[str, float], enabled: bool = True, stream=None, every: float = 30.0):
        self.estimates = dict(estimates)
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.every = every
        self.t0 = time.perf_counter()
        self.stage = ""
        self.stage_t0 = self.t0
        self.detail = ""
        self.probe: Callable[[], float] | None = None
        self.fraction = 0.0
        self._first: tuple[float, float] | None = None  # (time, fraction) of the first progress
        self._last_detail = None
        self._last_print = 0.0
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    # -- control
    def start(self) -> None:
        if self.enabled:
            self._thread = threading.Thread(target=self._loop, daemon=True)
            self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()

    def begin(self, stage: str, probe: Callable[[], float] | None = None) -> None:
        with self._lock:
            self.stage, self.stage_t0, self.probe, self.fraction, self.detail = stage, time.perf_counter(), probe, 0.0, ""
            self._first = None

    def set(self, detail: str | None = None, fraction: float | None = None) -> None:
        with self._lock:
            if detail is not None:
                self.detail = detail
            if fraction is not None:
                self._set_fraction(fraction)

    def _set_fraction(self, f: float) -> None:
        """Record progress (caller holds the lock); remember when it first moved, so that the
        rate excludes what came before it (compiling, loading, the work of a killed run)."""
        f = min(max(float(f), 0.0), 1.0)
        if self._first is None and f > self.fraction:
            self._first = (time.perf_counter(), f)
        self.fraction = f

    def message(self, text: str) -> None:
        """A permanent line (a stage's result) above the progress line."""
        if not self.enabled:
            return
        with self._lock:
            self.stream.write(("\r\033[K" if self.tty else "") + text + "\n")
            self.stream.flush()

    # -- rendering
    def eta(self) -> float | None:
        """Seconds left: the current stage extrapolated from its progress (or the cost model
        before it has any), plus the model's estimate of the stages after it."""
        if self.stage not in STAGES:
            return None
        i = STAGES.index(self.stage)
        now = time.perf_counter()
        spent = now - self.stage_t0
        f = self.fraction
        if self._first is not None and f - self._first[1] >= 0.02 and now - self._first[0] > 5:
            # the rate since progress first moved: compile time does not inflate the estimate
            left = (now - self._first[0]) * (1 - f) / (f - self._first[1])
        elif f >= 0.02 and spent > 5:
            left = spent * (1 - f) / f
        else:
            left = max(self.estimates.get(self.stage, 0.0) * (1 - f) - spent, 0.0)
        return left + sum(self.estimates.get(s, 0.0) for s in STAGES[i + 1:])

    def line(self) -> str:
        i = STAGES.index(self.stage) + 1 if self.stage in STAGES else 0
        return (f"reproduce [{i}/{len(STAGES)} {self.stage}] {self.detail} {100 * self.fraction:3.0f}% | "
                f"elapsed {_fmt_time(time.perf_counter() - self.t0)} | ETA {_fmt_time(self.eta())}")

    def _loop(self) -> None:
        while not self._stop.wait(1.0 if self.tty else 2.0):
            self.tick()

    def tick(self) -> None:
        probe = self.probe
        if probe is not None:
            try:
                f = float(probe())
                with self._lock:
                    self._set_fraction(f)
            except Exception:  # a file caught mid-replace: try again next tick
                pass
        with self._lock:
            text = self.line()
            now = time.perf_counter()
            if self.tty:
                self.stream.write("\r\033[K" + text)
                self.stream.flush()
            elif (self.stage, self.detail) != self._last_detail or now - self._last_print >= self.every:
                self.stream.write(text + "\n")
                self.stream.flush()
                self._last_detail, self._last_print = (self.stage, self.detail), now


# --------------------------------------------------------------------------- the run


@dataclasses.dataclass
class Run:
    """State of one ``reproduce`` invocation."""

    paths: Paths
    preset: str
    cfg: ReproduceConfig
    seed: int
    jobs: int
    force: tuple[str, ...]
    progress: Progress
    rollout_factory: Callable
    feature_factory: Callable
    feature_config: Callable
    log: dict
    entry: dict

    def save(self) -> None:
        rio.atomic_write_json(self.paths.log, self.log)


def _stage_generate(run: Run) -> dict:
    from relaff_jax.data import dataset as D

    cfg, paths = run.cfg, run.paths
    if "generate" in run.force:
        _remove(paths.data)
    dcfg = D.DatasetConfig(max_rollouts=cfg.max_rollouts, distance_bins=cfg.distance_bins,
                           borrow_fraction=cfg.borrow_fraction)
    half = cfg.n_samples // 2
    acts = cfg.actions
    items: dict[str, Any] = {}
    state = {"i": 0}

    def probe() -> float:
        i = state["i"]
        part = 0.0
        if i < len(acts):
            side = paths.dataset(acts[i]) / D.SIDECAR
            if side.exists():
                meta = rio.read_json(side)
                part = 1.0 if meta.get("status") == "complete" else min(meta["counts"]["positives"], half) / half
        return (i + part) / len(acts)

    run.progress.begin("generate", probe)
    for i, action in enumerate(acts):
        state["i"] = i
        run.progress.set(f"{action} ({i + 1}/{len(acts)})")
        path = paths.dataset(action)
        seed = run.log["seeds"]["datasets"][action]
        t0 = time.perf_counter()
        if _dataset_complete(path, action, cfg.n_samples, seed, cfg.rollout_batch):
            items[action] = {"status": "skipped"}
            continue
        fn, config_dict, names = run.rollout_factory(action, cfg.rollout_batch)
        s = D.generate_dataset(path, action, cfg.n_samples, fn, seed, cfg.rollout_batch, config_dict,
                               progress=False, dataset_config=dcfg, object_names=names)
        dt = time.perf_counter() - t0
        items[action] = {"status": "ran", "seconds": round(dt, 2), "rollouts": s["rollouts"],
                         "new_rollouts": s["new_chunks"] * cfg.rollout_batch, "positive_rate": s["positive_rate"],
                         "borrowed": s["borrowed"]}
        run.progress.message(f"generate {action}: {cfg.n_samples} samples from {s['rollouts']} rollouts "
                             f"(positive rate {s['positive_rate']:.1%}) in {dt:.0f} s")
    state["i"] = len(acts)
    return items


def _stage_features(run: Run) -> dict:
    from relaff_jax.data import dataset as D

    cfg, paths = run.cfg, run.paths
    fseed = run.log["seeds"]["features"]
    want = run.feature_config(fseed)
    chunks = math.ceil(cfg.n_samples / cfg.feature_batch)
    acts = cfg.actions
    items: dict[str, Any] = {}
    state = {"i": 0}
    compute = None

    def probe() -> float:
        i = state["i"]
        part = 0.0
        if i < len(acts):
            side = paths.dataset(acts[i]) / D.FEATURES_SIDECAR
            if side.exists():
                part = min(rio.read_json(side)["chunks"] / chunks, 1.0)
        return (i + part) / len(acts)

    run.progress.begin("features", probe)
    for i, action in enumerate(acts):
        state["i"] = i
        run.progress.set(f"{action} ({i + 1}/{len(acts)})")
        path = paths.dataset(action)
        st = _features_state(path, cfg.feature_batch, want)
        if st == "complete" and "features" not in run.force:
            items[action] = {"status": "skipped"}
            continue
        t0 = time.perf_counter()
        if compute is None:
            compute, config_dict = run.feature_factory(fseed)
        D.add_features(path, compute, cfg.feature_batch, False, config_dict,
                       overwrite="features" in run.force or st == "stale")
        dt = time.perf_counter() - t0
        items[action] = {"status": "ran", "seconds": round(dt, 2), "was": st}
        run.progress.message(f"features {action}: {cfg.n_samples} scenes in {dt:.0f} s")
    state["i"] = len(acts)
    return items


def _load_datasets(run: Run) -> dict[str, dict]:
    from relaff_jax.data.dataset import load_dataset

    out = {}
    for a in run.cfg.actions:
        d = load_dataset(run.paths.dataset(a))
        if "pca" not in d or "rhf" not in d:
            raise ReproduceError(f"{run.paths.dataset(a)} has no features; run the features stage")
        out[a] = d
    return out


def _experiment_valid(run: Run, datasets) -> str:
    """'absent', 'complete', 'partial' (resumable) or 'stale' (another config, seed or data)."""
    from relaff_jax.learn import experiment as E

    res = run.paths.results
    meta_path = res / "experiment.json"
    if not meta_path.exists():
        return "partial" if res.exists() else "absent"
    try:
        meta = rio.read_json(meta_path)
    except ValueError:
        return "stale"
    now = json.loads(json.dumps({"config": to_dict(run.cfg.experiment), "seed": run.log["seeds"]["experiment"],
                                 "fingerprint": E.fingerprint(datasets, run.cfg.spaces)}, default=rio._json_default))
    if meta.get("config") != now["config"] or meta.get("seed") != now["seed"] or meta.get("actions") != list(run.cfg.actions):
        return "stale"
    if any(meta.get("fingerprint", {}).get(s) != now["fingerprint"][s] for s in run.cfg.spaces
           if s in meta.get("fingerprint", {})):
        return "stale"
    return "complete" if E.is_complete(res, run.cfg.spaces) else "partial"


def _stage_experiment(run: Run) -> dict:
    from relaff_jax.learn import experiment as E

    cfg, res = run.cfg, run.paths.results
    ec = cfg.experiment
    a = len(cfg.actions)
    n_chunks = math.ceil(len(ec.sizes) / ec.sizes_per_block)
    weights = {}
    for s in cfg.spaces:
        fams = ec.conditions(s)
        weights[s] = (1 + ("DB1" in fams) * (a - 1) + ("DBn" in fams) + ("CB1" in fams) * (a - 1) * (a - 2) // 2) \
            * ec.reps(s) * len(ec.sizes)

    def probe() -> float:
        done = 0.0
        for s in cfg.spaces:
            total = ec.reps(s) * a * n_chunks
            blocks = len(list((res / s / "blocks").glob("*.npz"))) if (res / s / "blocks").exists() else 0
            frac = 1.0 if (res / s / "results.npz").exists() else 0.1 * (res / s / "prep.npz").exists() + 0.9 * blocks / total
            done += weights[s] * frac
        return done / sum(weights.values())

    run.progress.begin("experiment", probe)
    run.progress.set("loading datasets")
    datasets = _load_datasets(run)
    if "experiment" in run.force:
        _remove(res)
        state = "forced"
    else:
        state = _experiment_valid(run, datasets)
        if state == "complete":
            return {"status": "skipped"}
        if state == "stale":
            run.progress.message(f"experiment: {res} was computed from other data or settings; recomputing")
            _remove(res)
    run.progress.set(f"{' + '.join(s.upper() for s in cfg.spaces)} sweeps")
    t0 = time.perf_counter()
    E.run_experiment(datasets, res, ec, list(cfg.spaces), seed=run.log["seeds"]["experiment"], jobs=run.jobs,
                     progress=False, data_desc=[str(run.paths.dataset(x)) for x in cfg.actions])
    dt = time.perf_counter() - t0
    run.progress.message(f"experiment: {', '.join(cfg.spaces)} sweeps in {dt:.0f} s")
    return {"status": "ran", "was": state, "seconds": round(dt, 2)}


def _report_inputs(run: Run) -> list[Path]:
    from relaff_jax.data import dataset as D

    res = run.paths.results
    files = [res / "experiment.json"] + [res / s / "results.npz" for s in run.cfg.spaces]
    for a in run.cfg.actions:
        files += [run.paths.dataset(a) / D.SIDECAR, run.paths.dataset(a) / D.FEATURES_SIDECAR]
    return files


def _stage_report(run: Run) -> dict:
    from relaff_jax.report import report as R

    out = run.paths.report
    run.progress.begin("report", None)
    stamp = {"inputs": _hash_files(_report_inputs(run)), "examples_per_action": run.cfg.examples_per_action}
    if "report" in run.force:
        _remove(out)
    elif (out / REPORT_STAMP).exists() and all((out / f).exists() for f in ("report.md", "report.html", "summary.json")):
        try:
            if rio.read_json(out / REPORT_STAMP) == stamp:
                return {"status": "skipped"}
        except ValueError:
            pass
    with_stamp = out / REPORT_STAMP
    if with_stamp.exists():
        with_stamp.unlink()  # the report is being rewritten: no stamp until it is whole again
    run.progress.set("tables, figures, example scenes")
    t0 = time.perf_counter()
    info = {"preset": run.preset, "seed": run.seed, "versions": run.log["versions"],
            "timings": {s: round(t, 1) for s, t in run.log["timings"].items()}}
    R.write_full_report(run.paths.results, out, {a: run.paths.dataset(a) for a in run.cfg.actions}, info,
                        run.cfg.examples_per_action)
    rio.atomic_write_json(with_stamp, stamp)
    dt = time.perf_counter() - t0
    run.progress.message(f"report: {out / 'report.html'} in {dt:.0f} s")
    return {"status": "ran", "seconds": round(dt, 2)}


STAGE_FUNCS = {"generate": _stage_generate, "features": _stage_features,
               "experiment": _stage_experiment, "report": _stage_report}


def reproduce(out: str | os.PathLike, preset_name: str = "quick", seed: int = 0, *,
              force: Sequence[str] = (), jobs: int = 0, progress: bool = True,
              overrides: Mapping[str, Any] | None = None, cfg: ReproduceConfig | None = None,
              rollout_factory: Callable | None = None, feature_factory: Callable | None = None,
              feature_config_fn: Callable | None = None, argv: Sequence[str] | None = None,
              stream=None) -> dict[str, Any]:
    """Run (or continue) the whole study in ``out``; return the run log.

    preset_name: ``tiny``, ``quick`` or ``paper`` (``cfg`` replaces it; ``overrides`` are
    ``config.override`` keys, e.g. ``{"n_samples": 400, "experiment.reps_pca": 5}``).
    force: stages to redo. jobs: experiment worker processes (0: all cores).
    rollout_factory(action, batch) -> (rollout_fn, config_dict, object_names) and
    feature_factory(seed) -> (compute_fn, config_dict) replace the simulation and the
    perception (tests); ``feature_config_fn(seed)`` must then give the factory's config_dict.
    """
    if preset_name not in PRESETS:
        raise ReproduceError(f"unknown preset {preset_name!r}; expected one of {', '.join(PRESETS)}")
    bad = [s for s in force if s not in STAGES]
    if bad:
        raise ReproduceError(f"--force takes a stage name ({', '.join(STAGES)}), got {', '.join(map(str, bad))}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 0:
        raise ReproduceError(f"jobs must be an integer >= 0, got {jobs!r}")
    try:
        cfg = override(cfg or preset(preset_name), dict(overrides or {}))
    except ConfigError as e:
        raise ReproduceError(str(e)) from e
    check_config(cfg, seed)
    if feature_factory is not None and feature_config_fn is None:
        raise ReproduceError("a custom feature_factory needs feature_config_fn (its config_dict per seed)")
    jobs = jobs or (os.cpu_count() or 1)
    paths = Paths(Path(out))
    log = _open_log(paths, preset_name, cfg, seed)
    _clean_leftovers(paths.root)
    entry = {"started": _now(), "argv": list(argv) if argv is not None else None, "jobs": jobs,
             "force": list(force), "status": "running", "stages": {}}
    log["runs"].append(entry)
    prog = Progress(estimate_seconds(cfg, jobs), enabled=progress, stream=stream)
    run = Run(paths, preset_name, cfg, int(seed), jobs, tuple(force), prog,
              rollout_factory or default_rollout_factory, feature_factory or default_feature_factory,
              feature_config_fn or feature_config, log, entry)
    run.save()
    prog.start()
    t_run = time.perf_counter()
    stage, t0 = None, t_run
    # log["timings"][stage]: wall time spent computing the stage's current output, summed over
    # the runs that worked on it (a killed run's part included); a forced stage starts over.
    for stage in run.force:
        log["timings"].pop(stage, None)
    try:
        for stage in STAGES:
            t0 = time.perf_counter()
            result = STAGE_FUNCS[stage](run)
            dt = time.perf_counter() - t0
            items = result if stage in ("generate", "features") else None
            ran = any(v.get("status") == "ran" for v in items.values()) if items is not None else result["status"] == "ran"
            entry["stages"][stage] = {"status": "ran" if ran else "skipped", "seconds": round(dt, 2),
                                      **({"actions": items} if items is not None else {k: v for k, v in result.items() if k != "status"})}
            if ran:
                log["timings"][stage] = round(log["timings"].get(stage, 0.0) + dt, 2)
            else:
                prog.message(f"{stage}: complete, skipped")
            run.save()
        entry["status"] = "complete"
    except BaseException as e:
        dt = time.perf_counter() - t0
        log["timings"][stage] = round(log["timings"].get(stage, 0.0) + dt, 2)
        entry["stages"][stage] = {"status": "interrupted", "seconds": round(dt, 2)}
        what = "interrupted" if isinstance(e, KeyboardInterrupt) else f"failed: {type(e).__name__}: {e}"
        entry["status"] = f"{what} (in {stage})"
        raise
    finally:
        entry["finished"] = _now()
        entry["seconds"] = round(time.perf_counter() - t_run, 2)
        prog.close()
        run.save()
    return log


# --------------------------------------------------------------------------------- CLI


def _parse_set(items: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ReproduceError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            v = json.loads(value)
        except json.JSONDecodeError:
            v = value
        out[key.strip()] = tuple(v) if isinstance(v, list) else v
    return out


def _cmd_reproduce(args: argparse.Namespace) -> int:
    command = ["relaff", "reproduce", "--preset", args.preset, "--out", str(args.out), "--seed", str(args.seed)]
    command += [x for f in args.force or () for x in ("--force", f)] + (["--jobs", str(args.jobs)] if args.jobs else [])
    command += [x for s in args.set or () for x in ("--set", s)] + (["--no-progress"] if args.no_progress else [])
    log = reproduce(args.out, args.preset, args.seed, force=tuple(args.force or ()), jobs=args.jobs,
                    progress=not args.no_progress, overrides=_parse_set(args.set or []), argv=command)
    run = log["runs"][-1]
    for stage in STAGES:
        st = run["stages"][stage]
        print(f"{stage:<10} {st['status']:<8} {st['seconds']:8.1f} s")
    print(f"total {run['seconds']:.1f} s; report: {Path(args.out) / 'report' / 'report.html'}")
    return 0


def register_cli(subparsers) -> None:
    """Add ``relaff reproduce``."""
    p = subparsers.add_parser(
        "reproduce", help="run the whole study: datasets, features, experiment, report (resumable)",
        description="Generate the nine datasets, their features, the learning and bootstrapping experiment and "
                    "the report in OUT. Rerunning continues where a killed run stopped; finished stages are skipped.")
    p.add_argument("--preset", choices=PRESETS, default="quick",
                   help="quick: ~10 min on 2 idle cores (default); paper: the full protocol; tiny: for tests")
    p.add_argument("--out", required=True, metavar="DIR", help="run folder (created, or continued)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="append", choices=STAGES, metavar="STAGE",
                   help=f"redo a stage ({', '.join(STAGES)}); may be repeated")
    p.add_argument("--jobs", type=int, default=0, help="experiment worker processes (default: all cores)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a preset field, e.g. --set n_samples=400 --set experiment.reps_pca=5")
    p.add_argument("--no-progress", action="store_true", help="no progress line")
    p.set_defaults(func=_cmd_reproduce)
