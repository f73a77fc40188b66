"""The simulation stage's commands: ``relaff objects``, ``relaff scenes``, ``relaff generate``.

Takes an argparse subparsers object; ``register(subparsers)`` adds the three subcommands with
``set_defaults(func=...)``; each ``cmd_*(args) -> int`` returns the exit code. A mistake the
user can fix raises ``relaff_jax.errors.UserError`` (printed as one line by the CLI).
The heavy modules (JAX, MJX, the dataset store) are imported when a command runs.
"""
from __future__ import annotations

import json
from pathlib import Path

from relaff_jax.cli import options
from relaff_jax.constants import ACTIONS, RELATIONS, SIM_ENGINES
from relaff_jax.errors import UserError
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.sim.actions.registry import action_id
from relaff_jax import data as ds
from relaff_jax.data.validate import check_dataset_dir


def register(subparsers) -> None:
    """Add ``objects``, ``scenes`` and ``generate`` to ``subparsers``."""
    d = DatasetConfig()
    p = subparsers.add_parser("objects", help="list the 29 built-in objects, and a library file's",
                              description="List the 29 built-in objects (sim.objects) and, with --library, "
                                          "those of an object library file merged with them, checked as a run "
                                          "checks them (docs/objects.md).")
    p.add_argument("--library", metavar="FILE", default=None,
                   help="an object library (.toml or .json) to check and list after the built-ins")
    p.add_argument("--json", action="store_true", help="one JSON array")
    p.set_defaults(func=cmd_objects)

    p = subparsers.add_parser("scenes", help="sample and settle N mixed scenes in MJX, print a summary")
    p.add_argument("n", type=int, help="number of scenes")
    p.add_argument("--seed", type=int, default=0, help="seed of the placements")
    p.add_argument("--batch", type=int, default=1024, help="scenes per compiled batch (memory bound)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_objects(p)
    options.add_set(p, "action.scene.p_stacked=0.8")
    p.set_defaults(func=cmd_scenes)

    p = subparsers.add_parser(
        "generate",
        help="simulate an action on sampled scenes and write a balanced, resumable dataset",
        description="Sample and settle scenes, run the action's motor program (in MJX, or in MuJoCo C "
        "with --engine native), label by physics, and keep N samples with 50% positives (negatives "
        "matched to the positives' COG-distance distribution). Rerun with the same arguments to resume "
        "an interrupted run. N beyond the rollout cap (--max-rollouts) is refused at once.",
    )
    p.add_argument("action", help=f"one of: {', '.join(ACTIONS)}, or a user action registered by --plugins")
    p.add_argument("--samples", type=int, required=True, help="balanced samples to keep (N >= 2)")
    p.add_argument("--out", required=True, help="dataset directory (new, empty or resumable)")
    p.add_argument("--seed", type=int, default=None, help="seed of the dataset, every chunk's key derives from it "
                   "(the tree's seed key) (default: 0)")
    p.add_argument("--batch", type=int, default=None,
                   help=f"scenes per simulated chunk, the same as --set dataset.rollout_batch=B (default: "
                        f"{d.rollout_batch}; the presets of relaff reproduce use 8 to 1024); part of the "
                        "dataset's identity: a resume must use the same")
    p.add_argument("--max-rollouts", type=int, default=None,
                   help=f"stop after this many rollouts, the same as --set dataset.max_rollouts=M (default: "
                        f"{d.max_rollouts}); --samples beyond what it can give is refused at once")
    p.add_argument("--engine", choices=SIM_ENGINES, default=None,
                   help="executor of the motor programs: mjx (default) or native (MuJoCo C batches on a thread "
                        "pool, docs/actions.md); recorded in the dataset, a resume with another is refused")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    _add_objects(p)
    options.add_cluster(p)
    options.add_plugins(p)
    options.add_set(p, "action.lift_height=0.3")
    p.set_defaults(func=cmd_generate)


def _add_objects(p) -> None:
    p.add_argument("--objects", metavar="FILE", default=None,
                   help="an object library (.toml or .json) whose objects join the 29 built-ins, the same as "
                        "--set action.scene.library=FILE (docs/objects.md); recorded in the dataset")


def cmd_objects(args) -> int:
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.sim import object_library as ol
    from relaff_jax.sim import objects as lib

    specs = ol.select(ol.load_library(args.library), ()).specs if args.library else lib.OBJECTS.values()
    rows = [s.to_json() for s in specs]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"{'name':15s} {'groups':11s} {'kind':10s} {'size (cm)':>18s} {'mass':>6s}  colour")
    for r in rows:
        size = "x".join(f"{v:g}" for v in r["size_cm"])
        print(f"{r['name']:15s} {'+'.join(r['groups']):11s} {r['kind']:10s} {size:>18s} "
              f"{r['mass_kg']:6.2f}  {tuple(r['colour'])}")
    counts = {g: sum(g in s.groups for s in specs) for g in lib.GROUPS}
    print(f"{len(rows)} objects: " + ", ".join(f"{v} {k}s" for k, v in counts.items()))
    return 0


def cmd_scenes(args) -> int:
    options.check_counts(args, seed="--seed")
    if args.n < 1 or args.batch < 1:
        raise UserError(f"N and --batch are counts >= 1, got {args.n} and {args.batch}")
    options.precheck(args)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.sim import scenes as sc
    from relaff_jax.sim import world as wd

    cfg = options.config(args, flags={"action.scene.library": ("--objects", args.objects)})
    world = wd.build_world(cfg.action.phys)
    scenes, stats = sc.run_scenes(args.n, args.seed, args.batch, world=world, cfg=cfg.action.scene,
                                  progress=not args.json)
    s = sc.summary(world, scenes, stats)
    if args.json:
        print(json.dumps(s))
        return 0
    print(f"{s['n']} scenes settled in {s['seconds']:.1f} s ({s['scenes_per_second']:.1f} scenes/s), "
          f"{s['compilations']} compilation(s), {s['at_rest']} at rest")
    print("relations: " + ", ".join(f"{k} {v}" for k, v in s["relations"].items()))
    for pg, row in s["pairings"].items():
        print(f"  {pg:13s} n={row['n']:6d}  " + "  ".join(f"{r}={row[r]}" for r in RELATIONS))
    print(f"sampler intent agrees with the settled relation in {100 * s['intended_agrees']:.1f} %")
    return 0


def cmd_generate(args) -> int:
    options.load_plugins(args)  # a user action is registered before its name is checked

    action_id(args.action)
    options.check_counts(args, seed="--seed")
    options.check_out_dir(Path(args.out))  # before any simulation (minutes) or world building
    # the flags are aliases of tree keys: everything below reads the tree, which is what is recorded
    tree = options.config(args, flags={
        "dataset.n_samples": ("--samples", args.samples), "dataset.rollout_batch": ("--batch", args.batch),
        "dataset.max_rollouts": ("--max-rollouts", args.max_rollouts), "dataset.engine": ("--engine", args.engine),
        "action.scene.library": ("--objects", args.objects), "seed": ("--seed", args.seed)})
    n, batch = tree.dataset.n_samples, tree.dataset.rollout_batch  # checked by DatasetConfig itself

    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.stages.generate import generate_one

    engine = tree.dataset.engine
    from relaff_jax.reproduce.progress import sample_bound

    bound = sample_bound(n, tree.dataset.max_rollouts, batch, engine,
                         names=("--samples", "--max-rollouts (dataset.max_rollouts)"))
    if bound:
        raise UserError(bound)
    options.check_action(args, args.action, tree.action)  # a user action's rules traced once, before any work

    # a foreign folder, or a dataset of other settings, refused before the motor programs compile
    check_dataset_dir(Path(args.out), {"action": args.action, "n_samples": n, "seed": tree.seed, "batch": batch,
                                       "engine": engine})
    with options.cluster(args, Path(args.out)) as client:
        try:  # the same stage function reproduce runs for each action
            summary = generate_one(tree, args.action, args.out, tree.seed, client=client, progress=not args.json)
        except ds.DatasetError as e:
            if isinstance(e, UserError):
                raise
            raise UserError(str(e)) from e
    if args.json:
        print(json.dumps(summary, default=str))
    else:
        print(f"{args.action}: {n} samples written to {args.out} after "
              f"{summary.get('rollouts')} rollouts (positive rate over all rollouts "
              f"{summary.get('positive_rate', float('nan')):.3f})")
    return 0
