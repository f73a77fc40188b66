"""The whole sim-to-real study on a scenes folder and its labels file (and, optionally, a
test folder and its labels), resumable.

Takes a training folder and its labels CSV, optionally a test folder and its labels, an output
folder and the one ``config.RunConfig`` tree (its ``real`` node and ``perception``);
``run_study`` does, each step stored in the output folder and skipped when already there:

1. the camera poses of the training folder's labelled scenes: their mean is the simulated
   sensor (``sensor.json``: the pose from the *training* folder; the test folder's mean pose
   and the simulated folder's own sensor beside it), checked against the simulated folder's
   guard (``sim_relations.guard``: reused within ``cfg.tolerance``, refused with the reason
   otherwise) before any feature is computed;
2. ``real_features.npz`` (and ``real_features_test.npz``): features of the labelled pairs
   (``real_data``);
3. ``sim/`` (or ``--sim``): simulated relation scenes seen by that sensor (``sim_relations``);
4. ``raw_<space>.npz``: the four experiments within the training folder (``experiments.run_space``,
   split by ``cfg.experiment.split``) and SIM -> SIM for every pair of relations
   (``run_sim_only``); with a test folder also ``raw_<space>_cross.npz``: trained on the
   training folder, tested on the test folder; each keyed by the experiment config, the
   labelled rows and the simulated counts (a change recomputes);
5. the report (``report.write_report``): figures, ``results.json``, ``results.md``, the
   claims decided on the cross-folder figures when there is a test folder.
Returns ``dict(within={space: summary}, cross={space: summary} or None)``. Every check that
depends only on the inputs (output folders, settings, labels files against their scenes,
enough pairs of each relation for the split, enough simulated scenes for SIM_full) is made
first, by ``check_inputs``, before any work; ``only_present`` keeps the labelled scenes a
folder holds (the skipped ones are counted).
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from relaff_jax import io as rio
from relaff_jax.errors import UserError

from . import labels as lab
from . import folder as layout
from relaff_jax.config.real import pipeline_config, real_experiment, sensor_difference
from relaff_jax.constants import RELATIONS, SPACES
from . import splits
from .scene_source import object_ids
from .sim_relations import _counts, features_record
from . import experiments as ex
from . import real_data, report
from . import sim_relations as sr
from relaff_jax.provenance import record_config


SUMMARY_ONLY = ("bf_sizes", "n_boot")  # RealExperimentConfig keys only the summary reads: no refit


def _raw(path: Path, key: str):
    if path.exists():
        with np.load(path) as z:
            if str(z["key"]) == key:
                return {k: z[k] for k in z.files if k != "key"}
    return None


def _rows(scenes: str | Path, labels_path: str | Path, only_present: bool, what: str) -> tuple[list, list]:
    """The labelled rows of a folder (all, or with ``only_present`` those of the scenes it holds)
    and the skipped scene names; ``UserError`` when none is left."""
    rows = lab.read_labels(labels_path)
    skipped: list[str] = []
    if only_present:
        rows, skipped = lab.present(rows, scenes)
    if not rows:
        raise UserError(f"{labels_path} labels no pair" + (f" of a scene in {scenes} ({what})" if only_present else ""))
    return rows, skipped


def check_inputs(tree, scenes: str | Path, labels_path: str | Path, out: str | Path,
                 spaces: tuple[str, ...] = ("pca", "rhf"), sim_folder: str | Path | None = None,
                 test: str | Path | None = None, test_labels: str | Path | None = None,
                 only_present: bool = False) -> dict:
    """Raise ``UserError`` for any problem ``run_study`` would otherwise meet only after minutes
    of work; return ``dict(train=rows, test=rows or None, skipped_train=[names], skipped_test=[names])``.
    Reads the labels files and the scenes' object ids only."""
    rio.check_writable_dir(out, "--out")
    if sim_folder is not None:
        rio.check_writable_dir(sim_folder, "--sim")
    bad = [s for s in spaces if s not in SPACES]
    if not spaces or bad:
        raise UserError(f"spaces must be values of {', '.join(SPACES)}, got {list(spaces)}")
    cfg = tree.real  # checked with the perception it shares by config.check_tree
    exp_cfg, sim_cfg = real_experiment(tree), cfg.sim
    full = 2 * (exp_cfg.n_full // 2)
    sim_dir = Path(sim_folder) if sim_folder else Path(out) / layout.SIM
    have = _counts(sim_dir)[1] if sim_dir.is_dir() else np.zeros(len(RELATIONS), np.int64)
    held = min(int(have[RELATIONS.index(r)]) for r in ("beside", "on_top"))
    if sim_cfg.per_relation < full and held < full:  # the simulation would stop short of SIM_full
        raise UserError(f"SIM_full needs {full} simulated scenes of each relation (n_full {exp_cfg.n_full} to train, "
                        f"as many to test), but per_relation is {sim_cfg.per_relation}: raise --per-relation or lower --n-full")
    rows, skipped = _rows(scenes, labels_path, only_present, "training folder")
    y = np.asarray([int(x.relation == "on_top") for x in rows])
    try:  # the real pairs are the labelled ones, so their split is known now (a cross study splits its
        # training folder too, for the within-folder figures beside the cross-folder ones)
        sz = splits.split_sizes(y, exp_cfg.train_fraction)
        if exp_cfg.split == "scene":
            splits.scene_splits(y, [x.scene for x in rows], sz, exp_cfg.seed, exp_cfg.reps)
    except UserError as e:
        raise UserError(f"{labels_path}: {e}") from None
    out_rows = dict(train=lab.validate(rows, scenes, object_ids), test=None, skipped_train=skipped, skipped_test=[])
    if test is not None:
        if test_labels is None:
            raise UserError("--test needs --test-labels (the test folder's labels file)")
        trows, tskipped = _rows(test, test_labels, only_present, "test folder")
        ty = np.asarray([int(x.relation == "on_top") for x in trows])
        if min(ty.sum(), (1 - ty).sum()) < 1:
            raise UserError(f"{test_labels}: the test folder needs >= 1 pair of each relation, have "
                            f"{int((1 - ty).sum())} beside and {int(ty.sum())} on_top")
        out_rows.update(test=lab.validate(trows, test, object_ids), skipped_test=tskipped)
    return out_rows


def perception_key(perception) -> str:
    """The experiments' resume key part of the shared perception (voxel grid, RHF): empty for
    the default, so the folders made before the tree's perception reached the study keep theirs."""
    rec = features_record(perception)
    return "" if rec == features_record(None) else json.dumps(rec, sort_keys=True)


def _pose_stats(poses: dict) -> dict:
    return dict(scenes=len(poses["pose_scene"]), height=float(np.mean(poses["height"])),
                tilt_deg=float(np.mean(poses["tilt_deg"])), height_std=float(np.std(poses["height"])),
                tilt_std_deg=float(np.std(poses["tilt_deg"])))


def _experiments(path: Path, key: str, run) -> dict:
    res = _raw(path, key)
    if res is None:
        res = run()
        rio.atomic_save_npz(path, key=np.asarray(key), **res)
    return res


def run_study(tree, scenes: str | Path, labels_path: str | Path, out: str | Path,
              spaces: tuple[str, ...] = ("pca", "rhf"), sim_folder: str | Path | None = None,
              test: str | Path | None = None, test_labels: str | Path | None = None,
              only_present: bool = False, progress: bool = True, say=print) -> dict:
    """Run (or resume) the study with the ``RunConfig`` ``tree`` (its ``real`` node and its
    ``perception``, shared by the real and simulated features); see the module docstring."""
    out = Path(out)
    rows = check_inputs(tree, scenes, labels_path, out, spaces, sim_folder, test, test_labels, only_present)
    cfg, pipeline = tree.real, pipeline_config(tree)
    exp_cfg, sim_cfg = real_experiment(tree), cfg.sim
    poses = real_data.scene_poses(scenes, rows["train"], progress)
    sensor = real_data.sensor(poses)  # the simulated sensor: the training folder's mean pose
    sim_dir = Path(sim_folder) if sim_folder else out / layout.SIM
    # refused here, before the features
    simulated = sr.guard(sim_dir, sensor, sim_cfg, cfg.tolerance, perception=tree.perception)
    test_poses = real_data.scene_poses(test, rows["test"], progress) if test is not None else None
    out.mkdir(parents=True, exist_ok=True)
    rio.atomic_write_json(out / layout.SENSOR, dict(
        dataclasses.asdict(sensor), scenes=len(poses["pose_scene"]), height_std=float(np.std(poses["height"])),
        tilt_std_deg=float(np.std(poses["tilt_deg"])), source="the training folder's labelled scenes (mean pose)",
        simulated=dataclasses.asdict(simulated),
        simulated_difference=sensor_difference(simulated, sensor), tolerance=dataclasses.asdict(cfg.tolerance),
        test=_pose_stats(test_poses) if test_poses is not None else None))
    real = real_data.cached_real_features(out / layout.REAL_FEATURES, scenes, rows["train"], pipeline, progress)
    real_t = None if test is None else real_data.cached_real_features(
        out / layout.REAL_FEATURES_TEST, test, rows["test"], pipeline, progress)
    sim_summary = sr.build_sim_relations(sim_dir, sensor, sim_cfg, progress, cfg.tolerance, tree.perception)
    sim = sr.load_sim_relations(sim_dir)
    fits = {k: v for k, v in dataclasses.asdict(exp_cfg).items() if k not in SUMMARY_ONLY}  # what the fits depend on
    key = json.dumps(fits, sort_keys=True) + lab.rows_sha256(rows["train"]) + \
        json.dumps(sim_summary["counts"], sort_keys=True) + "+sim_only" + sr.normals_note(sim_cfg, pipeline) + \
        perception_key(tree.perception) + "+pairs"
    raw, summary, craw, cross = {}, {}, {}, {}
    for space in spaces:
        def within(space=space):
            res = ex.run_space(real, sim, space, exp_cfg, progress)
            res.update(ex.run_sim_only(sim, space, exp_cfg))
            return res
        raw[space] = _experiments(out / layout.raw(space), key, within)
        summary[space] = ex.summarise(raw[space], exp_cfg)
        if real_t is not None:
            ckey = key + "+cross+hits2" + lab.rows_sha256(rows["test"])
            craw[space] = _experiments(out / layout.raw(space, cross=True), ckey,
                                       lambda space=space: ex.run_space(real, sim, space, exp_cfg, progress, test=real_t))
            cross[space] = ex.summarise(craw[space], exp_cfg)
    context = _context(rows, real, real_t, sensor, simulated, test_poses, sim_summary, cfg, scenes, test, exp_cfg)
    report.write_report(out, raw, summary, context, craw or None, cross or None)
    for line in report.terminal_lines(summary, cross or None):
        say(line)

    record_config(out, tree, "real study")  # the tree that ran, as every stage's folder holds it
    return dict(within=summary, cross=cross or None)


def _context(rows, real, real_t, sensor, simulated, test_poses, sim_summary, cfg, scenes, test, exp_cfg) -> dict:
    """The ``results.md`` header: the data, the sensor (where it came from), the costs."""
    def pairs(rs, data, skipped, folder):
        c = lab.relation_counts(rs)
        extra = f"; {len(skipped)} labelled scenes not in the folder skipped (--only-present)" if skipped else ""
        return f"{folder}: {c['beside']} beside, {c['on_top']} on_top in {len(set(data['scene'].tolist()))} scenes{extra}"

    d = sensor_difference(simulated, sensor)
    reuse = "" if not any(d.values()) else (
        f"; the simulated folder's own sensor (height {simulated.height:.4f} m, tilt {simulated.tilt_deg:.2f} deg, "
        f"fov {simulated.vfov_deg:.2f} deg) is reused, within the tolerance "
        f"{dataclasses.asdict(cfg.tolerance)} (differences {', '.join(f'{k} {v:.4g}' for k, v in d.items())})")
    ctx = {"real pairs, training folder": pairs(rows["train"], real, rows["skipped_train"], scenes)}
    if real_t is not None:
        ctx["real pairs, test folder"] = pairs(rows["test"], real_t, rows["skipped_test"], test)
        ctx["test folder's camera"] = (f"mean height {np.mean(test_poses['height']):.4f} m, tilt "
                                       f"{np.mean(test_poses['tilt_deg']):.2f} deg over {len(test_poses['height'])} scenes")
    sim_cfg = cfg.sim
    ctx.update({
        "simulated sensor": f"from the training folder's mean pose: height {sensor.height:.4f} m, tilt "
                            f"{sensor.tilt_deg:.2f} deg from straight down, vertical fov {sensor.vfov_deg:.2f} deg, "
                            f"noise {sim_cfg.noise}{reuse}",
        "simulated scenes": f"{sim_summary['counts']} kept of {sim_summary['scenes']} "
                            f"(dropped: {sim_summary['dropped']})",
        "simulated cost": f"{sim_summary['seconds_per_scene']} s per scene (settle + perceive, "
                          f"{sim_summary['chunks_timed']} chunks timed, first one with compilation)",
        "RHF normals": sr.normals_note(sim_cfg, cfg.pipeline),
        "real split within a folder": f"by {exp_cfg.split}" + (" (pairs drawn one by one: pairs of a scene may be on "
                                                                "both sides)" if exp_cfg.split == "pair" else
                                                                " (every pair of a scene on one side)"),
        "forests": f"{exp_cfg.trees} trees, engine {exp_cfg.engine}; seed {exp_cfg.seed}",
    })
    return ctx
