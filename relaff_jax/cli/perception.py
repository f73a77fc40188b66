"""The perception commands of ``relaff``: ``features`` and ``show``.

``register(subparsers)`` adds both subcommands; each sets ``func(args) -> int`` (exit code).

* ``relaff features DIR [--batch B] [--seed S] [--overwrite]``: attach PCA and RHF features
  to the dataset in DIR (resumable; ``stages.features.add_features``, what reproduce runs).
* ``relaff show DIR [--index I] [--out scene.png]``: draw what the robot saw in sample I
  (``perception.from_sim.show_scene``), with the noise key ``show_key(rollout_id)``.

Mistakes a user can fix (an index out of range, an ``--out`` that cannot be written) are
``UserError``s, raised before any simulation or compilation starts.
"""
from __future__ import annotations

from pathlib import Path

from relaff_jax.cli import options
from relaff_jax.cli.options import check_out_file
from relaff_jax.config.dataset import DatasetConfig


def register(subparsers) -> None:
    """Add ``features`` and ``show`` to an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "features", help="add PCA and RHF features to a dataset (resumable)",
        description="Render every selected sample of a finished dataset with the simulated Kinect, voxelise "
                    "the two objects' clouds and attach their PCA (18) and RHF (300) features (docs/perception.md). "
                    "Resumable chunk by chunk; features of another perception config are refused unless "
                    "--overwrite.")
    p.add_argument("dir", type=Path, help="a finished dataset folder (relaff generate)")
    p.add_argument("--batch", type=int, default=None,
                   help="scenes per compiled chunk, the same as --set dataset.feature_batch=B (default: "
                        f"{DatasetConfig().feature_batch})")
    p.add_argument("--seed", type=int, default=None, help="depth-noise seed (the tree's seed key) (default: 0)")
    p.add_argument("--overwrite", action="store_true", help="recompute features of another config")
    options.add_cluster(p)
    options.add_set(p, "perception.voxel.size=0.02")
    p.set_defaults(func=cmd_features)

    p = subparsers.add_parser(
        "show", help="draw what the robot saw in one sample of a dataset",
        description="Draw sample --index of a dataset as the robot saw it (depth image, segmentation, "
                    "voxel clouds, PCA frames) into a PNG, or with --rollout animate its motor program, "
                    "replayed in MuJoCo C with the dataset's recorded action config (--set action.* "
                    "changes it) and ray cast shape by shape, as a GIF.")
    p.add_argument("dir", type=Path, help="a dataset folder")
    p.add_argument("--index", type=int, default=0, help="which selected sample (0 .. N-1)")
    p.add_argument("--out", type=Path, default=None, help="scene.png (default), or action.gif with --rollout")
    p.add_argument("--rollout", action="store_true",
                   help="animate the sample's motor program (replayed in MuJoCo C) as a GIF instead")
    options.add_plugins(p)
    options.add_set(p, "action.lift_height=0.3")
    p.set_defaults(func=cmd_show)


def cmd_features(args) -> int:
    """``relaff features``: attach features, print their shapes."""
    options.check_counts(args, seed="--seed")
    options.precheck(args)
    options.check_in_dir(args.dir)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.stages.features import add_features

    tree = options.config(args, flags={"dataset.feature_batch": ("--batch", args.batch), "seed": ("--seed", args.seed)})
    with options.cluster(args, args.dir) as client:  # the same stage function reproduce runs
        out = add_features(tree, args.dir, tree.seed, overwrite=args.overwrite, client=client)
    print(f"{args.dir}: features for {out['n']} samples: "
          + ", ".join(f"{k} {tuple(v)}" for k, v in out["features"].items()))
    return 0


def cmd_show(args) -> int:
    """``relaff show``: draw sample ``--index`` of the dataset into ``--out``."""
    options.load_plugins(args)  # a user action's dataset replays with its spec (checked against the record)
    options.check_counts(args, index="--index")
    options.precheck(args)
    options.check_in_dir(args.dir)
    out = args.out or Path("action.gif" if args.rollout else "scene.png")
    check_out_file(out)
    tree = options.config(args)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.data.show import show_sample

    bars = options.PhaseBars("show") if args.rollout else None
    import sys

    say = lambda m: print(f"show: {m}", file=sys.stderr, flush=True)  # noqa: E731
    try:
        acts = {k[len("action."):]: v for k, v in options.overrides_of(args).items() if k.startswith("action.")}
        print(show_sample(tree, args.dir, args.index, out, rollout=args.rollout, progress=bars, action_overrides=acts,
                          say=say))
    finally:
        if bars is not None:
            bars.close()
    return 0
