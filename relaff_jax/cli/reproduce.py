"""``relaff reproduce``: the whole study, resumable (``relaff_jax.reproduce``)."""
from __future__ import annotations

import argparse
from pathlib import Path

from relaff_jax.cli import options
from relaff_jax.constants import SIM_ENGINES, STAGES
from relaff_jax.errors import UserError
from relaff_jax.config import precheck, PRESETS
from relaff_jax import io as rio
from relaff_jax.sim.actions.registry import action_id


def register(sub) -> None:
    p = sub.add_parser(
        "reproduce", help="run the whole study: datasets, features, experiment, report (resumable)",
        description="Generate one balanced dataset per action, their features, the learning and bootstrapping "
                    "experiment and the report in OUT. Rerunning continues where a killed run stopped; finished "
                    "stages are skipped. Settings: a preset plus --set overrides of the config tree "
                    "(relaff_jax.config); the run log records the whole resolved tree.")
    p.add_argument("--preset", choices=PRESETS, default="quick",
                   help="quick: a small complete study, its motor programs in MuJoCo C; study: the smallest whose "
                        "Table II reads beside the paper's; paper: the full protocol; tiny: for tests "
                        "(docs/reproduce.md 'Presets'; measured times: docs/figures.json)")
    p.add_argument("--out", type=Path, metavar="DIR", default=None, help="run folder (created, or continued)")
    p.add_argument("dir", type=Path, nargs="?", default=None, metavar="DIR",
                   help="the run folder, as a positional argument for --status (same as --out DIR)")
    p.add_argument("--seed", type=int, default=None, help="run seed: every dataset, feature and forest seed "
                   "derives from it (the tree's seed key) (default: 0)")
    p.add_argument("--force", action="append", choices=STAGES, metavar="STAGE",
                   help=f"redo a stage ({', '.join(STAGES)}); may be repeated")
    p.add_argument("--redo-dataset", action="append", metavar="ACTION",
                   help="delete one action's dataset and make it again, keeping the other datasets (the repair "
                        "of one damaged dataset; later stages rerun only if their inputs changed); may be repeated")
    p.add_argument("--jobs", type=int, default=0, help="experiment worker processes (default: all cores)")
    options.add_cluster(p)
    options.add_set(p, "dataset.n_samples=400 --set experiment.reps_pca=5")
    p.add_argument("--engine", choices=SIM_ENGINES, default=None,
                   help="executor of the motor programs (same as --set dataset.engine=...): mjx (the default of "
                        "tiny, study and paper) or native (MuJoCo C batches, quick's default; docs/actions.md)")
    p.add_argument("--objects", metavar="FILE", default=None,
                   help="an object library (.toml or .json) whose objects join the 29 built-ins, the same as "
                        "--set action.scene.library=FILE (docs/objects.md); recorded in every dataset")
    p.add_argument("--status", action="store_true", help="print each stage's status in OUT and exit")
    p.add_argument("--rebuild-log", action="store_true",
                   help="OUT's run.json is damaged: set it aside (run.json.damaged) and start a new log for the "
                        "given --preset, --seed and --set; complete stages are then skipped")
    p.add_argument("--plugins", nargs="+", metavar="FILE.py", default=None,
                   help="Python files registering conditions, run where experiment.conditions_pca / "
                        "conditions_rhf name them (docs/extending.md)")
    p.add_argument("--no-progress", action="store_true", help="no progress line")
    p.add_argument("--no-compile-cache", action="store_true", default=argparse.SUPPRESS,
                   help="do not use JAX's persistent compilation cache (same as `relaff --no-compile-cache`)")
    p.set_defaults(func=cmd_reproduce)


def _print_log_summary(root: Path) -> dict:
    """The run log's figures, printed before the (slower) check of every stage's files: each
    invocation's start, status and wall time. Returns the per-stage ``timings`` (seconds spent
    computing each stage's current output). Nothing for a folder without a readable log (the
    stage check then says why)."""
    import sys

    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.reproduce.progress import human_time

    try:
        log = rio.read_json(root / "run.json")
        runs, timings = list(log["runs"]), dict(log.get("timings", {}))
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    print(f"{root}: preset {log.get('preset')}, seed {log.get('seed')}, {len(runs)} invocation(s); "
          f"computing time so far {human_time(sum(timings.values()))}")
    for r in runs[-3:]:
        secs, extra = r.get("seconds"), ""
        if r is runs[-1] and r.get("status") == "running":  # running now, or killed: its heartbeat says where
            try:
                beat = rio.read_json(root / ".run.heartbeat.json")
                extra = f" (last heartbeat {beat['at']}: {beat['stage']}, {human_time(beat['run_seconds'])} in)"
            except (OSError, ValueError, KeyError, TypeError):
                pass
        print(f"  {r.get('started', '?')}  {r.get('status', '?')}{extra}" + (f", {human_time(secs)}" if secs else ""))
    print(f"{'stage':<10} {'state':<9} {'time':>9}  why (checking the files...)")
    sys.stdout.flush()
    return timings


def cmd_reproduce(args: argparse.Namespace) -> int:
    if args.dir is not None and args.out is not None and args.dir != args.out:
        raise UserError(f"two run folders given: {args.dir} and --out {args.out}")
    if args.dir is not None and not args.status:
        raise UserError(f"give the run folder as --out {args.dir} (a positional folder is taken with --status only)")
    args.out = args.out if args.out is not None else args.dir
    if args.out is None:
        raise UserError("the run folder is required: --out DIR")
    options.check_counts(args, seed="--seed", jobs="--jobs")
    overrides = options.overrides_of(args, {"dataset.engine": ("--engine", args.engine), "seed": ("--seed", args.seed),
                                            "action.scene.library": ("--objects", args.objects)})
    seed = overrides.get("seed", 0)
    options.load_plugins(args)  # user actions registered before reproduce.actions names them

    for a in args.redo_dataset or ():  # one of the nine or a registered user action
        action_id(a)
    if not args.status:
        precheck(overrides)  # a mistyped key is reported before the stages (JAX) are imported
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax import reproduce as R
    from relaff_jax.report.folder import html
    from relaff_jax.reproduce.progress import human_time

    if args.status:
        timings = _print_log_summary(Path(args.out))  # from the run log at once; the stages' check reads their files
        for stage, st in R.status(args.out).items():
            t = timings.get(stage)
            print(f"{stage:<10} {st.state:<9} {'-' if t is None else human_time(t):>9}  {st.why}")
        return 0
    options.check_out_dir(args.out)
    if args.plugins:  # the user's conditions, registered before the study's config is checked
        # the learning package loads only when plugin files are given, not for --help
        from relaff_jax.learn import load_plugin_file

        for path in args.plugins:
            load_plugin_file(path)
    command = ["relaff", "reproduce", "--preset", args.preset, "--out", str(args.out), "--seed", str(seed)]
    command += [x for f in args.force or () for x in ("--force", f)]
    command += [x for a in args.redo_dataset or () for x in ("--redo-dataset", a)] + (["--jobs", str(args.jobs)] if args.jobs else [])
    command += [x for s in args.set or () for x in ("--set", s)] + (["--no-progress"] if args.no_progress else [])
    command += ["--cluster", args.cluster] if args.cluster else []
    command += ["--engine", args.engine] if args.engine else []
    command += ["--objects", args.objects] if args.objects else []
    command += ["--plugins", *args.plugins] if args.plugins else []
    with options.cluster(args, args.out) as client:
        log = R.reproduce(args.out, args.preset, seed, force=tuple(args.force or ()), jobs=args.jobs,
                          progress=not args.no_progress, overrides=overrides, argv=command,
                          client=client, rebuild_log=args.rebuild_log,
                          redo=tuple(args.redo_dataset or ()))
    run = log["runs"][-1]
    for stage in STAGES:
        st = run["stages"][stage]
        print(f"{stage:<10} {st['status']:<8} {st['seconds']:8.1f} s")
    print(f"total {run['seconds']:.1f} s; report: {html(R.Paths(Path(args.out)).report)}")
    return 0
