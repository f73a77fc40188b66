"""``relaff reproduce``: from nothing to the paper's results in one resumable command.

Takes a preset (``tiny``, ``quick``, ``study``, ``paper``; ``relaff_jax.config``), ``--set`` overrides,
a seed and a run folder (``folder.py``), and runs the four stages of ``relaff_jax.stages`` in order: ``generate`` ->
``features`` -> ``experiment`` -> ``report`` (one module each, keeping the contract of
``stages.protocol``). A stage whose status is ``complete`` is skipped; ``--force STAGE`` redoes one
stage (``--redo-dataset ACTION`` one action's dataset), and later stages follow only if their
inputs changed. Every stage writes atomically and
resumes, and every random quantity is seeded from the run seed, so a killed run, rerun, ends
with the results of an uninterrupted one.
"""
from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.cluster import nthreads
from relaff_jax.config import check_tree, from_json, override, preset, PRESETS, RunConfig
from relaff_jax.constants import STAGES
from relaff_jax.sim.actions.registry import names
from relaff_jax.errors import UserError
from relaff_jax.provenance import machine
from relaff_jax.reproduce.folder import ReproduceError, damaged_log_hint, now, open_log
from relaff_jax.reproduce.progress import Progress, estimate_seconds, sample_bound
from relaff_jax.stages import experiment, features, generate, report
from relaff_jax.stages.protocol import Hooks, Paths, Run, Silent, Stage, Status
from relaff_jax.learn.checks import check_config as check_experiment
from relaff_jax.learn import split_pools

STAGE_MODULES: dict[str, Stage] = {m.NAME: m for m in (generate, features, experiment, report)}
assert tuple(STAGE_MODULES) == STAGES


def check_config(cfg: RunConfig, seed: int) -> None:
    """Fail before any simulation if the config cannot give a complete study: the whole tree's
    check (``config.check_tree``; each node checked its own values when it was made), then
    what a study needs of several nodes at once."""
    try:
        check_tree(cfg)
        check_experiment(cfg.experiment)  # the learner and the user's conditions tried once, before any simulation
    except ReproduceError:
        raise
    except UserError as e:
        raise ReproduceError(str(e)) from e
    d = cfg.dataset
    bound = sample_bound(d.n_samples, d.max_rollouts, d.rollout_batch, d.engine)
    if bound:
        raise ReproduceError(bound)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ReproduceError(f"seed must be an integer in [0, 2**32), got {seed!r}")
    try:
        for i in range(len(names())):  # the learning pools of every action must fit in n_samples
            split_pools(d.n_samples, i, cfg.experiment, seed)
    except ValueError as e:
        raise ReproduceError(f"the experiment cannot run on {d.n_samples} samples per action: {e}") from e


def check_no_links(paths: Paths, force: Sequence[str], redo: Sequence[str]) -> None:
    """The folders ``--force`` and ``--redo-dataset`` delete must be folders, not symbolic
    links: refused before any work (``io.remove_tree`` does not delete through a link)."""
    doomed = {"generate": [paths.data], "experiment": [paths.results], "report": [paths.report]}
    for p in [q for s in force for q in doomed.get(s, [])] + [paths.dataset(a) for a in redo]:
        if p.is_symlink():
            flag = f"--redo-dataset {p.name}" if p.parent == paths.data and p != paths.data else "--force"
            raise ReproduceError(f"{p} is a symbolic link (to {os.readlink(p)}); {flag} deletes that folder and "
                                 "relaff does not delete through links: replace the link by the folder itself "
                                 "(or remove it) and rerun")


def reproduce(out: str | os.PathLike, preset_name: str = "quick", seed: int = 0, *,
              force: Sequence[str] = (), jobs: int = 0, progress: bool = True,
              overrides: Mapping[str, Any] | None = None, hooks: Hooks | None = None,
              argv: Sequence[str] | None = None, client: Any = None, rebuild_log: bool = False,
              redo: Sequence[str] = ()) -> dict[str, Any]:
    """Run (or continue) the whole study in ``out``; return the run log.

    preset_name: ``tiny``, ``quick``, ``study`` or ``paper``; ``overrides``: dotted keys of the
    config tree, e.g. ``{"dataset.n_samples": 400, "experiment.reps_pca": 5}``: every setting of
    the run comes from this one tree (``config.preset(preset_name)`` with the overrides).
    force: stages to redo. jobs: experiment worker processes (0: all cores).
    hooks: ``stages.protocol.Hooks``, stand-ins for the simulation, the perception and the
    progress line's stream (tests); None: the tree's own.
    client: a ``distributed.Client`` (``relaff_jax.cluster.connect``): dataset chunks, feature
    chunks and sweep blocks run as tasks on its cluster (the factories must be picklable);
    the results are those of the run without it, bit for bit.
    rebuild_log: ``out``'s run log is damaged; set it aside and start a new one for these
    settings (``folder.open_log``); the stages' own outputs decide what is skipped.
    redo: actions whose dataset (and so its features) is deleted and made again, the others
    kept (``--redo-dataset``: the repair of one damaged dataset); later stages rerun only if
    their inputs changed (the remade dataset is the lost one, bit for bit).

    One run at a time per folder: a second ``reproduce`` on ``out`` is refused while one runs.
    """
    if preset_name not in PRESETS:
        raise ReproduceError(f"unknown preset {preset_name!r}; expected one of {', '.join(PRESETS)}")
    bad = [s for s in force if s not in STAGES]
    if bad:
        raise ReproduceError(f"--force takes a stage name ({', '.join(STAGES)}), got {', '.join(map(str, bad))}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 0:
        raise ReproduceError(f"jobs must be an integer >= 0, got {jobs!r}")
    cfg = override(preset(preset_name), dict(overrides or {}))
    check_config(cfg, seed)
    if cfg.seed != seed:  # the tree records the run's seed (``--seed`` is its alias)
        if "seed" in dict(overrides or {}):
            raise ReproduceError(f"seed {seed} and --set seed={cfg.seed} disagree; give one of them")
        cfg = override(cfg, {"seed": int(seed)})
    redo = tuple(redo)
    bad = [a for a in redo if a not in cfg.reproduce.actions]
    if bad:
        raise ReproduceError(f"--redo-dataset takes an action of this study ({', '.join(cfg.reproduce.actions)}), "
                             f"got {', '.join(map(str, bad))}")
    if redo and "generate" in force:
        raise ReproduceError("--redo-dataset redoes some datasets, --force generate all of them: give one")
    paths = Paths(Path(out))
    root = paths.root
    try:
        rio.check_writable_dir(root)
    except UserError as e:
        raise ReproduceError(str(e)) from e
    check_no_links(paths, force, redo)
    if rebuild_log and not root.is_dir():
        raise ReproduceError(f"{root} does not exist: nothing to rebuild")
    os.makedirs(root, exist_ok=True)
    with rio.folder_lock(root, f"{root}: another relaff reproduce is running in this folder; wait for it "
                               "(or stop it) and rerun"):
        return _reproduce_locked(paths, preset_name, cfg, seed, force, jobs, progress, hooks or Hooks(), argv, client,
                                 rebuild_log, redo)


def bound_hooks(cfg: RunConfig, hooks: Hooks) -> tuple[Callable, Callable, Callable]:
    """``(rollout_factory, feature_factory, feature_config)``: ``hooks``' stand-ins, or the
    simulation and perception bound to ``cfg`` (``generate.rollout_factory_for``,
    ``features.factories_for``)."""
    default_features, default_feature_config = features.factories_for(cfg)
    return (hooks.rollout_factory or generate.rollout_factory_for(cfg), hooks.feature_factory or default_features,
            hooks.feature_config or default_feature_config)


def _reproduce_locked(paths: Paths, preset_name: str, cfg: RunConfig, seed: int, force: Sequence[str], jobs: int,
                      progress: bool, hooks: Hooks, argv, client, rebuild_log: bool, redo: tuple) -> dict[str, Any]:
    cpus = os.cpu_count() or 1
    jobs = jobs or cpus
    log = open_log(paths, preset_name, cfg, seed, rebuild=rebuild_log)
    fold_killed_run(paths, log)  # a run killed by SIGKILL: its last heartbeat says how long its stage ran
    rio.clean_leftovers(paths.root)
    for action in redo:  # the other datasets stay; later stages see changed inputs
        rio.remove_tree(paths.dataset(action))
    entry = {"started": now(), "argv": list(argv) if argv is not None else None, "jobs": jobs,
             "force": list(force), **({"redo": list(redo)} if redo else {}), "status": "running", "stages": {}}
    if client is not None:
        entry["cluster"] = {"scheduler": client.scheduler.address, "threads": nthreads(client)}
    here = machine()
    if here != log.get("machine"):
        # resumed on another machine (or VM build, or BLAS kernels): its stages' float bits
        # may differ from the first machine's (docs/reproduce.md), so the invocation says where
        entry["machine"] = here
    log["runs"].append(entry)
    prog = Progress(estimate_seconds(cfg, jobs, cpus), enabled=progress, stream=hooks.stream)
    # a run trusts no manifest: every stage it skips is verified chunk by chunk first
    run = Run(paths, preset_name, cfg, int(seed), jobs, tuple(force), prog, *bound_hooks(cfg, hooks), log, entry,
              client, verify=True)
    run.save()
    prog.start()
    t_run = time.perf_counter()
    stage, t0 = None, t_run
    beat = _Heartbeat(paths, lambda: (stage, time.perf_counter() - t0, time.perf_counter() - t_run))
    # log["timings"][stage]: wall time spent computing the stage's current output, summed over
    # the runs that worked on it (a killed run's part included); a forced stage starts over.
    for stage in run.force:
        log["timings"].pop(stage, None)
    try:
        for stage, module in STAGE_MODULES.items():
            t0 = time.perf_counter()
            forced = stage in run.force
            prog.begin(stage, lambda m=module: m.progress(run))
            st = None if forced else module.status(run)
            if st is not None and st.state == "complete":
                entry["stages"][stage] = {"status": "skipped", "seconds": round(time.perf_counter() - t0, 2), "why": st.why}
                prog.message(f"{stage}: complete, skipped")
                prog.done(stage)
                run.save()
                continue
            result = module.run(run, forced)
            dt = time.perf_counter() - t0
            items = result if stage in ("generate", "features") else None
            ran = any(v.get("status") == "ran" for v in items.values()) if items is not None else result["status"] == "ran"
            entry["stages"][stage] = {"status": "ran" if ran else "skipped", "seconds": round(dt, 2),
                                      **({"actions": items} if items is not None else
                                         {k: v for k, v in result.items() if k != "status"})}
            if ran:
                log["timings"][stage] = round(log["timings"].get(stage, 0.0) + dt, 2)
            prog.done(stage)
            run.save()
        entry["status"] = "complete"
    except BaseException as e:
        dt = time.perf_counter() - t0
        log["timings"][stage] = round(log["timings"].get(stage, 0.0) + dt, 2)
        entry["stages"][stage] = {"status": "interrupted", "seconds": round(dt, 2)}
        what = ("terminated (SIGTERM)" if type(e).__name__ == "Terminated" else "interrupted"
                if isinstance(e, KeyboardInterrupt) else f"failed: {type(e).__name__}: {e}")
        entry["status"] = f"{what} (in {stage})"
        raise
    finally:
        beat.stop()
        entry["finished"] = now()
        entry["seconds"] = round(time.perf_counter() - t_run, 2)
        prog.close()
        run.save()
    return log


HEARTBEAT = ".run.heartbeat.json"
HEARTBEAT_SECONDS = 15.0


class _Heartbeat:
    """Every ``HEARTBEAT_SECONDS`` the running stage and its seconds so far, in a small file
    of the run folder (not the run log: the log is the main thread's). A run killed by SIGKILL
    cannot write its log; the next run reads this file (``fold_killed_run``), so the time of
    the killed part of a stage is counted (to within one beat)."""

    def __init__(self, paths: Paths, where: Callable[[], tuple]):
        import threading

        self.path, self.where, self._stop = paths.root / HEARTBEAT, where, threading.Event()
        self._thread = threading.Thread(target=self._loop, name="relaff-heartbeat", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.wait(HEARTBEAT_SECONDS):
            stage, seconds, total = self.where()
            try:
                rio.atomic_write_json(self.path, {"stage": stage, "seconds": round(seconds, 2),
                                                  "run_seconds": round(total, 2), "at": now()})
            except (OSError, UserError):  # a full disk: the main thread reports it
                pass

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)  # the run log has the exact figures now


def fold_killed_run(paths: Paths, log: dict) -> None:
    """A last run entry still ``running`` was killed (SIGKILL, power): mark it so, with its
    stage's seconds from the heartbeat file added to the stage's timing."""
    last = log["runs"][-1] if log.get("runs") else None
    if not last or last.get("status") != "running":
        return
    try:
        beat = rio.read_json(paths.root / HEARTBEAT)
        stage, seconds = beat["stage"], float(beat["seconds"])
    except (OSError, ValueError, KeyError, TypeError):
        beat, stage, seconds = None, None, 0.0
    if stage in STAGES:
        log["timings"][stage] = round(log["timings"].get(stage, 0.0) + seconds, 2)
        last["stages"][stage] = {"status": "killed", "seconds": round(seconds, 2), "counted_until": beat["at"]}
        last["seconds"] = beat.get("run_seconds")
    last["status"] = f"killed (in {stage})" if stage else "killed (before its first heartbeat)"
    with contextlib.suppress(FileNotFoundError):
        os.unlink(paths.root / HEARTBEAT)


def status(out: str | os.PathLike, *, reference: bool = False) -> dict[str, Any]:
    """The status of every stage of an existing run folder (for ``relaff reproduce --status``).

    Finished datasets and features unchanged since their status manifest
    (``data.status.write_manifest``) are not read: their recorded state and fingerprints
    stand. ``reference``: read and verify every chunk as a rerun would trust nothing (the
    same states; ``benchmarks/status.py`` times both)."""
    paths = Paths(Path(out))
    if not paths.log.exists():
        raise ReproduceError(f"{out} holds no {paths.log.name}: not a relaff reproduce folder")
    try:
        log = rio.read_json(paths.log)
        cfg = from_json(log["config"])
        log["preset"], log["seed"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        why = e if not isinstance(e, (KeyError, TypeError)) else f"no valid {e} entry"
        raise ReproduceError(f"{paths.log} is damaged ({why}); {damaged_log_hint(paths.root)}") from None
    run = Run(paths, log["preset"], cfg, log["seed"], 1, (), Silent(), *bound_hooks(cfg, Hooks()), log, {},
              verify=reference)
    out = {}
    upstream = None  # the first stage that is not complete: every later one depends on it
    for name, m in STAGE_MODULES.items():
        try:
            st = m.status(run)
        except UserError as e:  # e.g. the experiment's inputs: a corrupt dataset upstream
            st = Status("stale", f"its inputs cannot be read ({e})")
        if upstream is not None and st.state == "complete":
            st = Status("stale", f"its own files are intact, but {upstream} is not complete: it is redone after it")
        if upstream is None and st.state != "complete":
            upstream = name
        out[name] = st
    return out
