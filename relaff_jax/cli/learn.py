"""``relaff experiment``, ``relaff report`` and ``relaff compare``: the learning sweeps, the report of
their results, and several readings of one study side by side.

Each command parses its arguments into the config tree (its flags are aliases of tree keys)
and makes one call: ``experiment`` runs (or resumes) ``stages.experiment.experiment_folder``
on dataset folders or synthetic data and prints the results paths; ``report`` runs
``stages.report.report_folder`` (Table II, findings, figures, the document) on a results folder;
``compare`` prints ``report.readings.compare_readings``. The stages check their inputs and
outputs before any work; problems a user can fix are ``relaff_jax.errors.UserError`` (one
line, exit code 2).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from relaff_jax.cli import options
from relaff_jax.constants import SPACES
from relaff_jax.sim.actions.registry import names  # the run's actions (no JAX)
from relaff_jax.errors import UserError
from relaff_jax.config.experiment import experiment_preset
from relaff_jax.config import RunConfig
from relaff_jax.data.store import read_sidecar

EXPERIMENT_DESCRIPTION = "The evaluation protocol of paper section V: sweeps, bootstrap factors and Table II."


def cmd_experiment(args: argparse.Namespace) -> int:
    if args.synthetic and args.data:
        raise UserError("give either --data or --synthetic, not both")
    if not args.synthetic and not args.data:
        raise UserError("give --data DIR... (one featured dataset per action) or --synthetic N")
    if args.synthetic < 0:
        raise UserError(f"--synthetic N takes a number of samples per action >= 1, got {args.synthetic}")
    options.check_counts(args, seed="--seed", jobs="--jobs")
    options.precheck(args)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax import learn

    for path in args.plugins or ():  # the user's conditions, registered before the config names them
        learn.load_plugin_file(path)

    spaces = {None: None, "both": tuple(SPACES)}.get(args.space, (args.space,))
    tree = options.config(args, base=RunConfig(experiment=experiment_preset(args.preset)),
                          flags={"reproduce.spaces": ("--space", spaces), "seed": ("--seed", args.seed)})
    options.check_out_dir(Path(args.out))  # before a --cluster client connects (seconds) and any work
    from relaff_jax.stages.experiment import experiment_folder

    with options.cluster(args, args.out) as client:  # the same stage function reproduce runs
        paths = experiment_folder(tree, args.data or args.synthetic, args.out, seed=tree.seed, jobs=args.jobs,
                                  client=client, progress=not args.no_progress, reuse=args.reuse)
    for space, p in paths.items():
        print(f"{space}: {p}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    tree = options.config(args)
    data_dirs = None
    if args.data:  # each folder's action from its sidecar, as the experiment read them
        data_dirs = {}
        for folder in args.data:
            action = read_sidecar(Path(folder))["action"]
            if action not in names():  # refused, not dropped: the report would silently lack it
                raise UserError(f"--data {folder}: its sidecar names the action {action!r}, not one of "
                                f"{', '.join(names())}" + ("" if action in names() else " (a user action: --plugins)"))
            if action in data_dirs:
                raise UserError(f"--data: {data_dirs[action]} and {folder} are both {action} datasets; give one")
            data_dirs[action] = folder
        data_dirs = {a: data_dirs[a] for a in names() if a in data_dirs}  # the run's order
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.stages.report import report_folder

    # the same stage function reproduce runs
    print(f"report: {report_folder(tree, args.results, args.out, data_dirs=data_dirs)}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax.report.readings import affordance_verdicts, compare

    if args.size < 1:
        raise UserError(f"--size is a training size >= 1, got {args.size}")
    reports, folders = {}, {}
    for item in args.readings:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise UserError(f"a reading is NAME=REPORT_DIR, got {item!r}")
        if name in reports:
            raise UserError(f"reading {name!r} given twice")
        real = Path(path).resolve()
        if real in folders:
            raise UserError(f"readings {folders[real]!r} and {name!r} are the same folder {path}; give different reports")
        reports[name], folders[real] = path, name
    page = compare(reports, args.out, size=args.size)
    if args.out:  # the page's headline answer in the terminal too
        print(f"wrote {args.out}")
        print("\n".join(affordance_verdicts(reports)))
    else:
        print(page, end="")
    return 0


def register(subparsers) -> None:
    """Add ``relaff experiment``, ``relaff report`` and ``relaff compare``."""
    p = subparsers.add_parser("experiment", help="learning curves and bootstrapping sweeps (paper section V)",
                              description=EXPERIMENT_DESCRIPTION)
    p.add_argument("--data", nargs="+", metavar="DIR", help="featured dataset folders, one per action")
    p.add_argument("--synthetic", type=int, metavar="N", default=0,
                   help="use N synthetic samples per action instead of --data (a dry run of the stage)")
    p.add_argument("--out", required=True, metavar="RESULTS", help="results folder (resumed if it exists)")
    p.add_argument("--preset", choices=("quick", "study", "paper"), default="quick",
                   help="the protocol's sizes, repetitions and forests (relaff_jax.config.experiment.experiment_preset)")
    p.add_argument("--space", choices=("pca", "rhf", "both"), default=None,
                   help="state space(s) to sweep, the same as --set reproduce.spaces=[...] (default: both)")
    p.add_argument("--seed", type=int, default=None, help="seed of the test draws, training orders and forests "
                   "(the tree's seed key) (default: 0)")
    p.add_argument("--jobs", type=int, default=0, help="worker processes (default: all cores)")
    options.add_cluster(p)
    options.add_set(p, "experiment.reps_pca=5 --set 'experiment.sizes=[2,10,25]'")
    p.add_argument("--plugins", nargs="+", metavar="FILE.py", default=None,
                   help="Python files registering conditions (@relaff_jax.learn.register_condition), run where "
                        "experiment.conditions_pca / conditions_rhf name them; see docs/extending.md")
    p.add_argument("--reuse", metavar="RESULTS", default=None,
                   help="another reading's experiment folder (same data, seed and protocol but for "
                        "experiment.dbn_repeats): its prep and every condition whose forests that setting does not "
                        "change are read from it instead of refitted, with the same bits (relaff_jax.learn.reuse)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_experiment)
    r = subparsers.add_parser(
        "report", help="Table II, findings, figures and report.html from an experiment folder",
        description="Read a finished experiment folder and write the report: Table II with intervals beside "
                    "the paper's numbers, every finding's verdict from its interval, Figs. 6-12, the "
                    "correlation clusters and the threshold study, as report.md, report.html and PNGs.")
    r.add_argument("results", metavar="RESULTS", help="a finished experiment folder (relaff experiment)")
    r.add_argument("--out", required=True, metavar="REPORT", help="report folder (created or replaced)")
    r.add_argument("--data", nargs="+", metavar="DIR", default=None,
                   help="the dataset folders the experiment learnt from (one per action): their statistics, "
                        "what the labels consist of, the datasets' figures and example scenes")
    options.add_set(r, "reproduce.examples_per_action=1")
    r.set_defaults(func=cmd_report)
    c = subparsers.add_parser("compare", help="the same study in two or more readings, side by side, from their reports",
                              description="Read the report folders of runs that differ in one setting (e.g. "
                              "dataset.population=all and feasible) and print one markdown page: what the labels "
                              "consist of, NB by test subset in PCA and RHF, the predictors' correlations with "
                              "feasible and stacked, the correlation clusters, Table II, every finding's verdict, each "
                              "affordance's answer in every run (verdict, gain, bf, samples saved, intervals, and whether "
                              "the verdict is the same in all) and, last, the robustness table: each finding's verdict and intervals in every reading (each "
                              "report and its after_ten readings) and whether it is reproduced in all of them.")
    c.add_argument("readings", nargs="+", metavar="NAME=REPORT_DIR",
                   help="two or more readings, each a name and a report folder, e.g. all=runs/a/report")
    c.add_argument("--size", type=int, default=10, help="training size of the NB comparison (default 10)")
    c.add_argument("--out", metavar="FILE.md", help="write the page here (default: print it)")
    c.set_defaults(func=cmd_compare)
