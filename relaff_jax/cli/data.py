"""``relaff info``, ``anatomy``, ``audit`` and ``export``: look at a dataset, audit its physics, or export it.

Takes parsed arguments; prints ``data.info`` as a table or JSON, or writes
``data.export_dataset``'s Parquet file, feature schema and dataset card. Problems a user can
fix are ``relaff_jax.errors.UserError`` (one line, exit code 2). None of the three has a setting
of the config tree (no ``--set``): they read the settings a dataset's sidecars record.
"""
from __future__ import annotations

import json

from relaff_jax import data as D
from relaff_jax.data import export as X
from relaff_jax.constants import ACTIONS
from relaff_jax.errors import UserError
from relaff_jax.cli import options


def _not_a_run_folder(path) -> None:
    """``relaff info RUN_FOLDER`` (a ``relaff reproduce`` folder, not a dataset): name the
    datasets it holds instead of "not a relaff dataset"."""
    from pathlib import Path

    root = Path(path)
    if (root / "run.json").is_file() and not (root / "relaff_dataset.json").exists():
        held = [a for a in ACTIONS if (root / "data" / a).is_dir()]
        where = ", ".join(str(root / "data" / a) for a in held[:3]) + (", ..." if len(held) > 3 else "")
        raise UserError(f"{root} is a relaff reproduce run folder, not a dataset; its datasets are "
                        f"{root / 'data'}/<action>" + (f" ({where})" if held else " (none made yet)"))


def _cmd_info(args) -> int:
    _not_a_run_folder(args.dir)
    d = D.info(args.dir)
    if args.json:
        print(json.dumps(d, sort_keys=True))
    else:
        print(D.format_info(d))
    return 0


def _cmd_anatomy(args) -> int:
    _not_a_run_folder(args.dir)
    d = D.anatomy(args.dir)
    print(json.dumps(d, sort_keys=True) if args.json else D.format_anatomy(d))
    return 0


def _cmd_export(args) -> int:
    # export_dataset checks --out and --format before it loads or writes anything
    _not_a_run_folder(args.dir)
    paths = D.export_dataset(args.dir, args.out, format=args.format, overwrite=args.overwrite)
    for p in paths.values():
        print(f"wrote {p}")
    return 0


def _cmd_audit(args) -> int:
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.data import audit as A

    if args.sample < 1:
        raise UserError(f"--sample must be >= 1, got {args.sample}")
    if args.seed < 0:
        raise UserError(f"--seed must be >= 0, got {args.seed}")
    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be >= 1, got {args.jobs}")

    options.load_plugins(args)  # a user action's datasets replay with its spec (checked against the record)
    folders = A.dataset_folders(args.dir)  # one-line errors before any work
    audits = [A.ensure_audit(f, args.sample, args.seed, jobs=args.jobs) for f in folders]
    if args.json:
        print(json.dumps(audits if len(audits) > 1 else audits[0], sort_keys=True))
    else:
        print(A.format_audit(audits))
    return 0


def register(subparsers) -> None:
    """Add ``relaff info DIR [--json]`` and ``relaff export DIR --out FILE_OR_DIR``."""
    p = subparsers.add_parser(
        "info",
        help="counts and positive rates of a dataset",
        description="Show counts, positive rates by spatial relation and by object pair, "
        "rollouts used and attached features of a relaff dataset. No settings (no --set): it "
        "reads what the dataset's own sidecars record.",
    )
    p.add_argument("dir", metavar="DIR", help="dataset directory")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=_cmd_info)

    p = subparsers.add_parser(
        "anatomy",
        help="what a dataset's labels consist of: reach or relation",
        description="Counts and label rates by (feasible, relation) over every rollout and over the "
        "balanced selection, the share of negatives that are infeasible, three oracles on the "
        "selection (label = feasible; the relation's majority label; both) and centre-distance "
        "quantiles by class and relation (docs/datasets.md, 'Population'). No settings (no --set): "
        "it reads what the dataset's own sidecars record.",
    )
    p.add_argument("dir", metavar="DIR", help="finished dataset directory")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=_cmd_anatomy)

    p = subparsers.add_parser(
        "audit",
        help="the physics of a sample of a dataset's rollouts, replayed in MuJoCo C",
        description="Replay a sample of a finished dataset's rollouts (the selected samples whose "
        "program ran) in MuJoCo C and check each step's contacts: palm (hand body) contacts with an "
        "object, the contact force on an object held over 0.1 s relative to the heavier object's weight, "
        "the deepest "
        "penetration, and the objects' speeds at the step where the goal is measured; and the replay's "
        "label agreement with the stored labels (docs/audit.md). DIR is a dataset or a run folder "
        "(every data/<action>/ dataset). Writes DIR/audit.json per dataset (reused when sample, seed "
        "and selection match). No settings (no --set): it replays with the dataset's recorded config.",
    )
    p.add_argument("dir", metavar="DIR", help="dataset folder or run folder")
    p.add_argument("--sample", type=int, default=64, help="rollouts audited per dataset")
    p.add_argument("--seed", type=int, default=0, help="seed of the sample")
    p.add_argument("--jobs", type=int, default=None,
                   help="processes replaying the rollouts (default: the cores; the same audit at any value)")
    p.add_argument("--json", action="store_true", help="print JSON (a list for a run folder) instead of a table")

    options.add_plugins(p)
    p.set_defaults(func=_cmd_audit)

    p = subparsers.add_parser(
        "export",
        help="export a dataset as Parquet with a feature schema and a dataset card",
        description="Write the selected samples of a finished dataset (labels, names, poses, "
        "PCA and RHF features when present) as one Parquet file, plus a JSON schema of the "
        "feature columns and a README dataset card. OUT ending in .parquet is the file "
        "(schema and card beside it as STEM.schema.json, STEM.md); any other OUT is a folder "
        "(data.parquet, features_schema.json, README.md). No tree settings (no --set): the "
        "card and schema copy the settings the dataset's sidecars record; --format is the only choice.",
    )
    p.add_argument("dir", metavar="DIR", help="dataset directory")
    p.add_argument("--out", required=True, metavar="FILE_OR_DIR", help="a .parquet file or a folder")
    p.add_argument("--format", default="parquet", choices=X.FORMATS, help="output format (default parquet)")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.set_defaults(func=_cmd_export)
