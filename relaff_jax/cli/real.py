"""The ``relaff real`` commands: real scenes, relation labels, the sim-to-real study (paper VI).

``register(subparsers)`` adds ``real`` with its own subcommands (``relaff real --help``):

* ``segment SCENES [--known-count] [--out iou.json]``: the paper's pipeline (RANSAC table,
  k-means) scored against the hand segmentation, IoU per object (``real.score``);
* ``show SCENE [--out scene.png] [--pair A B] [--source hand|pipeline]``: colour, segmentations,
  voxel clouds with PCA frames (``real.show``);
* ``propose SCENES --out labels.csv [--pictures DIR] [--corrections C.csv]``: the geometric
  rule's relation for every pair, pictures to check them by eye, corrections applied, the
  labels file with checksums (``real.labelling``);
* ``check SCENES --labels L``: validate a labels file against the scenes, count the pairs;
* ``study SCENES --labels L --out DIR``: real features, simulated relation scenes from the real
  sensor's pose, the four experiments, the report (``real.study``; resumable).
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

from relaff_jax.cli.options import check_in_dir, check_in_file, check_out_dir, check_out_file
from relaff_jax.errors import UserError


def register(subparsers) -> None:
    real = subparsers.add_parser(
        "real", help="real scenes: segmentation, relation labels, sim-to-real study",
        description="Real Kinect/Xtion scenes (a folder of .pcd, .ply or .npz clouds with hand segmentation, "
                    "docs/real.md): segment them as the paper does, propose and check relation labels, draw a "
                    "scene, and run the four sim-to-real experiments of paper section VI.")
    sub = real.add_subparsers(dest="real_command", metavar="SUBCOMMAND")
    sub.required = True

    p = sub.add_parser("segment", help="score the paper's segmentation against the hand labels (IoU)")
    p.add_argument("scenes", type=Path, help="folder of scene files (.pcd, .ply, .npz) with labels")
    p.add_argument("--known-count", action="store_true", help="k = objects + 1 instead of 3")
    p.add_argument("--seed", type=int, default=0, help="seed of the k-means initialisation")
    p.add_argument("--out", type=Path, default=None, help="write the per-scene figures as JSON")
    p.set_defaults(func=cmd_segment)

    p = sub.add_parser("show", help="draw a real scene: colour, segmentation, voxel clouds, PCA frames")
    p.add_argument("scene", type=Path, help="one scene file (.pcd, .ply or .npz)")
    p.add_argument("--out", type=Path, default=Path("scene.png"), help="PNG to write")
    p.add_argument("--pair", type=int, nargs=2, default=None, metavar=("A", "B"),
                   help="the two objects whose PCA frames and RHF are drawn (default: the first two)")
    p.add_argument("--source", choices=("hand", "pipeline"), default="hand",
                   help="objects from the hand segmentation, or from the paper's pipeline (k-means)")
    p.add_argument("--seed", type=int, default=0, help="seed of the pipeline's k-means")
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("propose", help="propose relation labels by the geometric rule (+ pictures)")
    p.add_argument("scenes", type=Path, help="folder of scene files")
    p.add_argument("--out", type=Path, required=True, help="labels CSV to write")
    p.add_argument("--pictures", type=Path, default=None, help="folder for one PNG per pair")
    p.add_argument("--corrections", type=Path, default=None,
                   help="CSV scene,object_a,object_b,relation (beside, on_top or none) overriding the rule")
    p.set_defaults(func=cmd_propose)

    p = sub.add_parser("check", help="validate a labels file against its scenes and count the pairs")
    p.add_argument("scenes", type=Path, help="folder of scene files")
    p.add_argument("--labels", type=Path, required=True, help="labels CSV (relaff real propose, or by hand)")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("study", help="the four experiments of paper VI and their report (resumable)")
    p.add_argument("scenes", type=Path, help="folder of scene files")
    p.add_argument("--labels", type=Path, required=True, help="labels CSV of its pairs")
    p.add_argument("--out", type=Path, required=True, help="study folder (created, or resumed)")
    p.add_argument("--sim", type=Path, default=None, help="simulated relation folder (default OUT/sim)")
    p.add_argument("--per-relation", type=int, default=1000, help="simulated scenes per relation (paper: thousands)")
    p.add_argument("--n-full", type=int, default=1000, help="SIM_full training samples (paper: 6500)")
    p.add_argument("--reps", type=int, default=50, help="repetitions of every train/test split")
    p.add_argument("--trees", type=int, default=100, help="trees per relation classifier")
    p.add_argument("--spaces", nargs="+", choices=("pca", "rhf"), default=["pca", "rhf"], help="state spaces")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated scenes, splits and forests")
    p.add_argument("--chunk", type=int, default=256, help="simulated scenes per chunk")
    p.add_argument("--sim-normals", choices=("ray", "cloud"), default="ray",
                   help="RHF normals of the simulated scenes: exact ray hits, or the cloud rule (5x5 pixel window)")
    p.add_argument("--real-normals", choices=("knn", "window"), default="knn",
                   help="RHF normals of the real scenes: 20 nearest neighbours, or the simulation's window rule")
    p.set_defaults(func=cmd_study)


def _corrections(path: Path | None) -> dict:
    if path is None:
        return {}
    if not path.is_file():
        raise UserError(f"corrections file {path} does not exist")
    out = {}
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or [c.strip() for c in rows[0]][:4] != ["scene", "object_a", "object_b", "relation"]:
        raise UserError(f"{path}: header must start scene,object_a,object_b,relation")
    for i, r in enumerate(rows[1:], start=2):
        if not r or r[0].startswith("#"):
            continue
        try:
            out[(r[0].strip(), int(r[1]), int(r[2]))] = r[3].strip()
        except (IndexError, ValueError):
            raise UserError(f"{path} line {i}: expected scene,object_a,object_b,relation") from None
    return out


def _check_inputs(args) -> None:
    """The scenes folder and the labels file exist: checked before the real stage is imported."""
    check_in_dir(args.scenes, f"scenes folder {args.scenes} does not exist")
    if getattr(args, "labels", None) is not None:
        check_in_file(args.labels, f"labels file {args.labels} does not exist")


def cmd_segment(args) -> int:
    _check_inputs(args)
    from relaff_jax.real import score_scenes
    from relaff_jax.real.scene_source import scene_files

    if args.out:
        check_out_file(args.out)  # before the segmentation (about a minute)
    res = score_scenes(scene_files(args.scenes), seed=args.seed, known_count=args.known_count)
    for s in res["scenes"]:
        print(f"{s['scene']}: mean object IoU {s['mean']:.3f}, table {s['table']:.3f}")
    print(f"mean IoU over scenes {res['mean_iou']:.3f}, over objects {res['mean_iou_objects']:.3f}, "
          f"table {res['mean_table_iou']:.3f}")
    if args.out:
        from relaff_jax.io import atomic_write_json

        atomic_write_json(args.out, res)
    return 0


def cmd_show(args) -> int:
    check_in_file(args.scene, f"scene file {args.scene} does not exist")
    check_out_file(args.out)
    import jax

    from relaff_jax.real import read_cloud, render_real_scene_png

    cloud = read_cloud(args.scene)
    render_real_scene_png(cloud, jax.random.PRNGKey(args.seed), args.out, pair=args.pair, source=args.source)
    print(args.out)
    return 0


def cmd_propose(args) -> int:
    _check_inputs(args)
    from relaff_jax.real import labels as lab
    from relaff_jax.real.labelling import propose_folder

    check_out_file(args.out)
    if args.pictures is not None:
        check_out_dir(args.pictures, "--pictures")
    corrections = _corrections(args.corrections)
    labels, record = propose_folder(args.scenes, args.pictures, corrections)
    lab.write_labels(args.out, labels)
    counts = lab.relation_counts(labels)
    left = sum(r[2] == "none" for r in record)
    print(f"{args.out}: {counts['beside']} beside, {counts['on_top']} on_top; {left} of {len(record)} pairs left out; "
          f"{len(corrections)} corrections applied")
    return 0


def cmd_check(args) -> int:
    _check_inputs(args)
    from relaff_jax.real import labels as lab
    from relaff_jax.real.scene_source import object_ids

    labels = lab.validate(lab.read_labels(args.labels), args.scenes, object_ids)
    counts = lab.relation_counts(labels)
    print(f"{args.labels}: valid; {counts['beside']} beside, {counts['on_top']} on_top in "
          f"{len({x.scene for x in labels})} scenes")
    return 0


def cmd_study(args) -> int:
    _check_inputs(args)
    from relaff_jax.real import experiments as ex
    from relaff_jax.real import sim_relations as sr
    from relaff_jax.real.study import run_study

    from relaff_jax.real.config import NormalConfig, RealConfig

    sim_cfg = sr.SimRelationConfig(per_relation=args.per_relation, chunk=args.chunk, seed=args.seed,
                                   normals=args.sim_normals)
    exp_cfg = ex.RealExperimentConfig(reps=args.reps, trees=args.trees, n_full=args.n_full, seed=args.seed)
    real_cfg = RealConfig(normals=NormalConfig(method=args.real_normals))
    summary = run_study(args.scenes, args.labels, args.out, sim_cfg, exp_cfg, tuple(args.spaces), args.sim,
                        real_cfg=real_cfg)
    for space, s in summary.items():
        acc = {k: round(v["mean"], 3) for k, v in s["accuracy"].items()}
        print(f"{space}: {json.dumps(acc)}; bf early {s['bf_early_mean']:.3f}")
    print(f"report: {args.out / 'results.md'}")
    return 0


__all__ = ["register"]
