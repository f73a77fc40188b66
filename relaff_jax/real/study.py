"""The whole sim-to-real study on one scenes folder and its labels file, resumable.

Takes a scenes folder, its labels CSV, an output folder and the configs; ``run_study`` does,
each step stored in the output folder and skipped when already there:

1. ``real_features.npz``: features of the labelled real pairs and the camera poses
   (``real_data``), whose mean gives the simulated sensor (``sensor.json``);
2. ``sim/``: simulated relation scenes seen by that sensor (``sim_relations``);
3. ``raw_<space>.npz``: the four experiments per space (``experiments.run_space``) and SIM ->
   SIM for every pair of relations, inside included (``run_sim_only``), keyed by the
   experiment config, the labels file and the simulated counts (a change recomputes);
4. the report (``report.write_report``): figures, ``results.json``, ``results.md``.
Returns the summary dict per space. Every check that depends only on the inputs (the output
folders, the settings, the labels file against its scenes, >= 2 pairs of each relation, enough
simulated scenes for SIM_full) is made first, by ``check_inputs``, before any work.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from relaff_jax import io as rio
from relaff_jax.errors import UserError

from . import experiments as ex
from . import labels as lab
from . import real_data, report
from . import sim_relations as sr
from .config import RealConfig


def _raw(path: Path, key: str):
    if path.exists():
        with np.load(path) as z:
            if str(z["key"]) == key:
                return {k: z[k] for k in z.files if k != "key"}
    return None


def check_inputs(scenes: str | Path, labels_path: str | Path, out: str | Path,
                 sim_cfg: sr.SimRelationConfig = sr.SimRelationConfig(),
                 exp_cfg: ex.RealExperimentConfig = ex.RealExperimentConfig(),
                 spaces: tuple[str, ...] = ("pca", "rhf"), sim_folder: str | Path | None = None,
                 real_cfg: RealConfig = RealConfig()) -> list:
    """Raise ``UserError`` for any problem ``run_study`` would otherwise meet only after minutes
    of work; return the validated labels. Reads the labels file and the scenes' object ids only."""
    from relaff_jax.constants import SPACES

    from .config import validate_real_config
    from .scene_source import object_ids

    rio.check_writable_dir(out, "--out")
    if sim_folder is not None:
        rio.check_writable_dir(sim_folder, "--sim")
    bad = [s for s in spaces if s not in SPACES]
    if not spaces or bad:
        raise UserError(f"spaces must be values of {', '.join(SPACES)}, got {list(spaces)}")
    for name, v, lo in (("reps", exp_cfg.reps, 1), ("trees", exp_cfg.trees, 1), ("n_full", exp_cfg.n_full, 2),
                        ("per_relation", sim_cfg.per_relation, 1), ("chunk", sim_cfg.chunk, 1)):
        if v < lo:
            raise UserError(f"{name} must be >= {lo}, got {v}")
    if sim_cfg.normals not in ("ray", "cloud"):
        raise UserError(f"unknown normals {sim_cfg.normals!r}; valid: ['ray', 'cloud']")
    if sim_cfg.chunk % sim_cfg.feature_batch:
        raise UserError(f"chunk ({sim_cfg.chunk}) must be a multiple of feature_batch ({sim_cfg.feature_batch})")
    full = 2 * (exp_cfg.n_full // 2)
    sim_dir = Path(sim_folder) if sim_folder else Path(out) / "sim"
    have = sr._counts(sim_dir)[1] if sim_dir.is_dir() else np.zeros(len(sr.RELATIONS), np.int64)
    held = min(int(have[sr.RELATIONS.index(r)]) for r in ("beside", "on_top"))
    if sim_cfg.per_relation < full and held < full:  # the simulation would stop short of SIM_full
        raise UserError(f"SIM_full needs {full} simulated scenes of each relation (n_full {exp_cfg.n_full} to train, "
                        f"as many to test), but per_relation is {sim_cfg.per_relation}: raise --per-relation or lower --n-full")
    validate_real_config(real_cfg)
    labels = lab.read_labels(labels_path)
    if not labels:
        raise UserError(f"{labels_path} labels no pair")
    try:  # the real pairs are the labelled ones, so their split is known now
        ex.split_sizes(np.asarray([int(x.relation == "on_top") for x in labels]), exp_cfg.train_fraction)
    except UserError as e:
        raise UserError(f"{labels_path}: {e}") from None
    return lab.validate(labels, scenes, object_ids)


def run_study(scenes: str | Path, labels_path: str | Path, out: str | Path,
              sim_cfg: sr.SimRelationConfig = sr.SimRelationConfig(),
              exp_cfg: ex.RealExperimentConfig = ex.RealExperimentConfig(),
              spaces: tuple[str, ...] = ("pca", "rhf"), sim_folder: str | Path | None = None,
              real_cfg: RealConfig = RealConfig(), progress: bool = True) -> dict:
    """Run (or resume) the study; see the module docstring."""
    out = Path(out)
    check_inputs(scenes, labels_path, out, sim_cfg, exp_cfg, spaces, sim_folder, real_cfg)
    real = real_data.cached_real_features(out / "real_features.npz", scenes, labels_path, real_cfg, progress)
    sensor = real_data.sensor(real)
    rio.atomic_write_json(out / "sensor.json", dict(
        dataclasses.asdict(sensor), scenes=len(real["pose_scene"]),
        height_std=float(np.std(real["height"])), tilt_std_deg=float(np.std(real["tilt_deg"]))))
    sim_dir = Path(sim_folder) if sim_folder else out / "sim"
    sim_summary = sr.build_sim_relations(sim_dir, sensor, sim_cfg, progress)
    sim = sr.load_sim_relations(sim_dir)
    key = json.dumps(dataclasses.asdict(exp_cfg), sort_keys=True) + lab.file_sha256(labels_path) + \
        json.dumps(sim_summary["counts"], sort_keys=True) + "+sim_only" + sr.normals_note(sim_cfg, real_cfg)
    raw, summary = {}, {}
    for space in spaces:
        path = out / f"raw_{space}.npz"
        res = _raw(path, key)
        if res is None:
            res = ex.run_space(real, sim, space, exp_cfg, progress)
            res.update(ex.run_sim_only(sim, space, exp_cfg))
            rio.atomic_save_npz(path, key=np.asarray(key), **res)
        raw[space], summary[space] = res, ex.summarise(res, exp_cfg)
    counts = lab.relation_counts(lab.read_labels(labels_path))
    context = {
        "real pairs (labels file)": f"{counts['beside']} beside, {counts['on_top']} on_top in "
                                    f"{len(set(real['scene'].tolist()))} scenes",
        "simulated sensor": f"height {sensor.height:.3f} m, tilt {sensor.tilt_deg:.1f} deg from straight down, "
                            f"vertical fov {sensor.vfov_deg:.1f} deg, noise {sim_cfg.noise}",
        "simulated scenes": f"{sim_summary['counts']} kept of {sim_summary['scenes']} "
                            f"(dropped: {sim_summary['dropped']})",
        "simulated cost": f"{sim_summary['seconds_per_scene']} s per scene (settle + perceive, "
                          f"{sim_summary['chunks_timed']} chunks timed, first one with compilation)",
        "RHF normals": sr.normals_note(sim_cfg, real_cfg),
        "forests": f"{exp_cfg.trees} trees, engine {exp_cfg.engine}; seed {exp_cfg.seed}",
    }
    report.write_report(out, raw, summary, context)
    return summary
