"""The ``relaff real`` commands: real scenes, relation labels, the sim-to-real study (paper VI).

``register(subparsers)`` adds ``real`` with its own subcommands (``relaff real --help``):

* ``segment SCENES [--known-count] [--out iou.json]``: the paper's pipeline (RANSAC table,
  k-means) scored against the hand segmentation, IoU per object (``real.score``);
* ``show SCENE [--out scene.png] [--pair A B] [--source hand|pipeline]``: colour, segmentations,
  voxel clouds with PCA frames (``real.show``);
* ``propose SCENES --out labels.csv [--pictures DIR] [--corrections C.csv]``: the geometric
  rule's relation for every pair, pictures to check them by eye, corrections applied, the
  labels file with checksums (``real.labelling``);
* ``check SCENES --labels L [--only-present] [--write-checksums]``: validate a labels file
  against the scenes, count the pairs (first writing its sha256 column with ``--write-checksums``);
* ``study SCENES --labels L --out DIR [--test T --test-labels TL] [--only-present]``: real
  features, simulated relation scenes from the training folder's sensor pose, the four
  experiments within the folder (split by scene unless ``--set real.experiment.split=pair``) and,
  with a test folder, trained on one folder and tested on the other; the report
  (``real.study``; resumable).

Every setting of the real stages is one key of the config tree (``config.RunConfig``): the
real-only ones under ``real.`` (``--set real.pipeline.kmeans.background=false``, ``--set
real.experiment.split=pair``, ``--set real.sim.per_relation=500``), the voxel grid and RHF shared
with simulation under ``perception.`` (``--set perception.voxel.size=0.02``); the flags are
shorthands for keys of that tree (``--set`` wins). The tree is resolved and checked without JAX,
so a mistyped key or a bad value is reported at once. ``check`` has no settings (no ``--set``).
"""
from __future__ import annotations

from pathlib import Path

from relaff_jax.cli.options import (add_set, check_counts, check_in_dir, check_in_file, check_out_dir, check_out_file,
                                    config)
from relaff_jax.errors import UserError

SET_EXAMPLE = "real.pipeline.kmeans.background=false"


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
    p.add_argument("--known-count", action="store_true",
                   help="k = objects + 1 clusters (objects + background) instead of pipeline.kmeans.k (3)")
    p.add_argument("--no-background", action="store_true",
                   help="no background cluster: every cluster is an object (with --known-count k = objects); "
                        "the same as --set pipeline.kmeans.background=false")
    p.add_argument("--seed", type=int, default=0, help="k-means seed (scene i gets fold_in(key(seed), i); default 0)")
    p.add_argument("--out", type=Path, default=None, help="write the per-scene figures as JSON")
    add_set(p, SET_EXAMPLE)
    p.set_defaults(func=cmd_segment)

    p = sub.add_parser("show", help="draw a real scene: colour, segmentation, voxel clouds, PCA frames")
    p.add_argument("scene", type=Path, help="one scene file (.pcd, .ply or .npz)")
    p.add_argument("--out", type=Path, default=Path("scene.png"), help="PNG to write")
    p.add_argument("--pair", type=int, nargs=2, default=None, metavar=("A", "B"),
                   help="the two objects whose PCA frames and RHF are drawn (default: the first two)")
    p.add_argument("--source", choices=("hand", "pipeline"), default="hand",
                   help="objects from the hand segmentation, or from the paper's pipeline (k-means)")
    p.add_argument("--seed", type=int, default=0, help="seed of the pipeline's k-means")
    add_set(p, SET_EXAMPLE)
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("propose", help="propose relation labels by the geometric rule (+ pictures)")
    p.add_argument("scenes", type=Path, help="folder of scene files")
    p.add_argument("--out", type=Path, required=True, help="labels CSV to write")
    p.add_argument("--pictures", type=Path, default=None, help="folder for one PNG per pair")
    p.add_argument("--corrections", type=Path, default=None,
                   help="CSV scene,object_a,object_b,relation (beside, on_top or none) overriding the rule")
    add_set(p, "real.rule.contact_tol=0.04")
    p.set_defaults(func=cmd_propose)

    p = sub.add_parser("check", help="validate a labels file against its scenes and count the pairs",
                       description="Validate a labels file against its scenes and count the pairs. No settings "
                                   "(no --set): it reads the labels and the scenes' object ids only.")
    p.add_argument("scenes", type=Path, help="folder of scene files")
    p.add_argument("--labels", type=Path, required=True, help="labels CSV (relaff real propose, or by hand)")
    p.add_argument("--only-present", action="store_true",
                   help="check only the labelled scenes the folder holds (and say how many were skipped)")
    p.add_argument("--write-checksums", action="store_true",
                   help="first write (or rewrite) the labels file's sha256 column from the scene files, in place "
                        "(a labels file made by hand or in a spreadsheet has none)")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("study", help="the four experiments of paper VI and their report (resumable)",
                       description="Real features, simulated relation data seen from the training folder's "
                                   "camera pose, the four experiments of paper VI within the training folder "
                                   "(split by scene by default) and, with --test, trained on the training folder "
                                   "and tested on the test folder; the report with claims a-d.")
    p.add_argument("scenes", type=Path, help="training folder of scene files")
    p.add_argument("--labels", type=Path, required=True, help="the training folder's labels CSV")
    p.add_argument("--test", type=Path, default=None, help="test folder of scene files (cross-folder figures)")
    p.add_argument("--test-labels", type=Path, default=None, help="the test folder's labels CSV")
    p.add_argument("--only-present", action="store_true",
                   help="use the labelled scenes each folder holds (one labels file may then serve both folders)")
    p.add_argument("--out", type=Path, required=True, help="output folder (resumable: finished steps are kept)")
    p.add_argument("--sim", type=Path, default=None,
                   help="simulated relation folder (default OUT/sim); reused when its sensor lies within "
                        "tolerance.* of the training folder's (defaults 0.01 m, 2.5 deg, 0.5 deg fov)")
    # the flags below are aliases of tree keys (default None: the tree's value); a flag and a
    # --set of its key that disagree are refused
    p.add_argument("--per-relation", type=int, default=None,
                   help="simulated scenes per relation (real.sim.per_relation; default 1000, paper: thousands)")
    p.add_argument("--n-full", type=int, default=None, help="SIM_full training samples (real.experiment.n_full; "
                                                             "default 1000, paper: 6500)")
    p.add_argument("--reps", type=int, default=None, help="repetitions (real.experiment.reps; default 50)")
    p.add_argument("--trees", type=int, default=None, help="trees per forest (real.experiment.trees; default 100)")
    p.add_argument("--split", choices=("scene", "pair"), default=None,
                   help="within a folder: every pair of a scene on one side (default), or pairs one by one "
                        "(real.experiment.split)")
    p.add_argument("--spaces", nargs="+", choices=("pca", "rhf"), default=["pca", "rhf"],
                   help="state spaces (default both)")
    p.add_argument("--seed", type=int, default=None, help="seed of the simulation and the experiments "
                                                           "(real.sim.seed and real.experiment.seed; default 0)")
    p.add_argument("--chunk", type=int, default=None, help="simulated scenes per chunk (real.sim.chunk; default 256)")
    p.add_argument("--sim-normals", choices=("ray", "cloud"), default=None,
                   help="RHF normals of the simulated scenes: exact ray hits (default), or the cloud rule "
                        "(5x5 pixel window; real.sim.normals)")
    p.add_argument("--real-normals", choices=("knn", "window"), default=None,
                   help="RHF normals of the real scenes: 20 nearest neighbours (default), or the simulation's "
                        "window rule (real.pipeline.normals.method)")
    add_set(p, "perception.voxel.size=0.02 (real scenes: real.pipeline.*, real.rule.*, real.sim.*, "
                "real.experiment.*, real.tolerance.*; voxel grid and RHF: perception.*)")
    p.set_defaults(func=cmd_study)


def real_config(args, flags: dict | None = None):
    """The resolved ``RunConfig`` tree: the command's flags, aliases of keys of its ``real``
    node (``{"sim.chunk": ("--chunk", args.chunk)}``; None: not given), and ``--set``; a flag
    and a ``--set`` of its key that disagree are refused. Its real settings (and the
    perception they share) are checked with the whole tree before any work, without importing
    JAX (``options.config``)."""
    return config(args, flags={f"real.{k}": v for k, v in (flags or {}).items()})


def _check_inputs(args) -> None:
    """The scenes folder and the labels file exist: checked before the real stage is imported."""
    check_in_dir(args.scenes, f"scenes folder {args.scenes} does not exist")
    if getattr(args, "labels", None) is not None:
        check_in_file(args.labels, f"labels file {args.labels} does not exist")


def cmd_segment(args) -> int:
    check_counts(args, seed="--seed")
    tree = real_config(args, {"pipeline.kmeans.background": ("--no-background", False if args.no_background else None)})
    _check_inputs(args)
    if args.out:
        check_out_file(args.out)  # before the segmentation (about a minute)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.real.stages import run_segment

    run_segment(tree, args.scenes, args.out, seed=args.seed, known_count=args.known_count)
    return 0


def cmd_show(args) -> int:
    check_counts(args, seed="--seed")
    tree = real_config(args)
    check_in_file(args.scene, f"scene file {args.scene} does not exist")
    check_out_file(args.out)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.real.stages import run_show

    run_show(tree, args.scene, args.out, seed=args.seed, pair=args.pair, source=args.source)
    return 0


def cmd_propose(args) -> int:
    tree = real_config(args)
    _check_inputs(args)
    check_out_file(args.out)
    if args.pictures is not None:
        check_out_dir(args.pictures, "--pictures")
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.real.stages import run_propose

    run_propose(tree, args.scenes, args.out, pictures=args.pictures, corrections=args.corrections)
    return 0


def cmd_check(args) -> int:
    _check_inputs(args)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.real.stages import run_check

    run_check(args.scenes, args.labels, only_present=args.only_present, write_checksums=args.write_checksums)
    return 0


def cmd_study(args) -> int:
    check_counts(args, seed="--seed")
    cfg = real_config(args, {
        "sim.per_relation": ("--per-relation", args.per_relation), "sim.chunk": ("--chunk", args.chunk),
        "sim.seed": ("--seed", args.seed), "sim.normals": ("--sim-normals", args.sim_normals),
        "experiment.reps": ("--reps", args.reps), "experiment.trees": ("--trees", args.trees),
        "experiment.n_full": ("--n-full", args.n_full), "experiment.seed": ("--seed", args.seed),
        "experiment.split": ("--split", args.split), "pipeline.normals.method": ("--real-normals", args.real_normals)})
    _check_inputs(args)
    if args.test is not None:
        check_in_dir(args.test, f"test folder {args.test} does not exist")
        if args.test_labels is None:
            raise UserError("--test needs --test-labels (the test folder's labels file)")
        check_in_file(args.test_labels, f"labels file {args.test_labels} does not exist")
    elif args.test_labels is not None:
        raise UserError("--test-labels needs --test (the test folder)")
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.real.stages import run_study

    run_study(cfg, args.scenes, args.labels, args.out, tuple(args.spaces), args.sim, args.test, args.test_labels,
              args.only_present)
    from relaff_jax.real.folder import RESULTS_MD

    print(f"report: {args.out / RESULTS_MD}")
    return 0


__all__ = ["register"]
