"""Where the report stage's time goes (issue 26), on a paper-shaped synthetic experiment folder;
reference path against the default one in the same run, outputs compared byte for byte.

    PYTHONPATH=. python benchmarks/report_stage.py --out /tmp/relaff_report_bench [--sizes 99]
        [--resamples 1000] [--variants reference new] [--profile]
    PYTHONPATH=. python benchmarks/report_stage.py --run RUN --out /tmp/relaff_report_run [--examples 2]

The folder (``learn.synthetic_results``: 9 actions, 50 conditions, 4,000 balanced test scenes,
50 PCA / 25 RHF repetitions, outcomes bit-packed as the sweep writes them, ``--sizes`` training
sizes 2, 3, ...) is built once in ``--out/results`` and reused. No ``--data``: the dataset
sections need dataset folders (see docs/journal/2026-12-04.md, "Report stage", for what that leaves out).

Each variant (``reference``: ``write_report(..., reference=True)``; ``new``: the default path;
``base``: the default path of another checkout, ``--base``) runs in its own process, with
timers wrapped around the writer's parts (inclusive seconds; a part's exclusive seconds leave
out the parts timed inside it; inclusive CPU seconds of the process, BLAS threads included),
and reports its peak RSS; ``--profile`` also writes a cProfile of each variant beside the
reports. The variants' report files (``findings.json``, ``summary.json``, ``reach.json``,
``affordances.csv``, Table II CSV and Markdown, the PNGs of Figs. 6-12) are compared byte for byte.

``--run RUN``: a finished ``relaff reproduce`` folder instead (``RUN/results`` and the datasets
``RUN/data/<action>``, ``--examples`` example scenes per action, as the stage writes them; the
folder is only read, the reports go to ``--out``); nothing is projected.

Projection to the paper preset when ``--sizes`` < 99: every part's time but the dataset
sections' times 99 / sizes (the outcomes and the resamples' curves grow with the sizes; the
few fixed costs, figures and small tables, are scaled too, so the projection is an upper
bound); the dataset sections as measured. ``--resamples`` below 1000 is not projected.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
COMPARED = ("findings.json", "summary.json", "reach.json", "table2.csv", "table2_rhf.csv", "table2.md", "affordances.csv",
            "fig06_nb_learning.png", "fig07_nb_spaces.png", "fig08_db1_best.png", "fig09_db1_best_bf.png",
            "fig10_average_bf.png", "fig11_correlation.png", "fig12_thresholds.png")

# (module, attribute, part name): wrapped where the writer and the analysis look them up
PARTS = [
    ("relaff_jax.report.write", "load_results", "load results.npz"),
    ("relaff_jax.report.write", "analyse", "analyse (space)"),
    ("relaff_jax.learn.analysis", "extend", "  online.extend"),
    ("relaff_jax.learn.analysis", "curves", "  curves"),
    ("relaff_jax.learn.analysis", "half_curves", "  half_curves"),
    ("relaff_jax.learn.analysis", "table2_rows", "  table2_rows"),
    ("relaff_jax.learn.analysis", "threshold_study", "  threshold_study"),
    ("relaff_jax.learn.analysis", "against_nb", "  against_nb"),
    ("relaff_jax.learn.analysis", "_intervals", "  _intervals"),
    ("relaff_jax.learn.analysis", "resampled_means", "    resampled_means"),
    ("relaff_jax.learn.analysis", "whole", "    whole"),
    ("relaff_jax.learn.analysis", "interval_pairs", "    interval_pairs"),
    ("relaff_jax.report.write", "user_rows", "user_rows"),
    ("relaff_jax.report.write", "table2_csv", "table2_csv"),
    ("relaff_jax.report.write", "table2_markdown", "table2_markdown"),
    ("relaff_jax.report.write", "write_figures", "figures (Figs. 6-12)"),
    ("relaff_jax.report.write", "borrow_rows", "borrow_rows"),
    ("relaff_jax.report.write", "summary", "summary"),
    ("relaff_jax.report.write", "reach_json", "reach_json"),
    ("relaff_jax.report.write", "findings", "findings"),
    ("relaff_jax.report.write", "dataset_info", "data: info"),
    ("relaff_jax.report.write", "anatomy", "data: anatomy"),
    ("relaff_jax.report.write", "dataset_figure", "data: dataset_figure"),
    ("relaff_jax.report.write", "reach_figure", "data: reach_figure"),
    ("relaff_jax.report.write", "reach_blocks", "data: reach_blocks"),
    ("relaff_jax.report.write", "subset_blocks", "data: subset_blocks"),
    ("relaff_jax.report.write", "stored_audits", "data: stored_audits"),
    ("relaff_jax.report.write", "audit_blocks", "data: audit_blocks"),
    ("relaff_jax.report.write", "examples_beside", "data: examples_beside (drawn in a second process)"),
    ("relaff_jax.report.write", "by_reading", "by_reading"),
    ("relaff_jax.report.write", "finite", "finite (json prep)"),
    ("relaff_jax.report.sections", "correlation_blocks", "correlation_blocks"),
    ("relaff_jax.report.sections", "threshold_blocks", "threshold_blocks"),
    ("relaff_jax.report.sections", "table2_blocks", "table2_blocks"),
    ("relaff_jax.report.write", "render_markdown", "render_markdown"),
    ("relaff_jax.report.write", "render_html", "render_html"),
    ("relaff_jax.io", "atomic_write_text", "file writes"),
]


def build(root: Path, sizes: int, resamples: int) -> Path:
    """The synthetic experiment folder ``root/results`` (reused when its config matches)."""
    from relaff_jax.config import to_dict
    from relaff_jax.config.experiment import ExperimentConfig
    from relaff_jax.learn.synthetic_results import write_synthetic_results

    cfg = ExperimentConfig(keep_outcomes=True, sizes=tuple(range(2, 2 + sizes)), ci_resamples=resamples)
    res = root / "results"
    meta = res / "experiment.json"
    if meta.exists() and json.loads(meta.read_text())["config"] == json.loads(json.dumps(to_dict(cfg))):
        return res
    t = time.perf_counter()
    write_synthetic_results(res, cfg)
    print(f"built {res} in {time.perf_counter() - t:.0f} s")
    return res


def build_data(root: Path, n: int) -> dict[str, str]:
    """Nine datasets of ``n`` balanced samples (``root/data/<action>``) written by the dataset
    stage's writer (``data.generate_dataset``) from a numpy stand-in for the simulator: labels
    by relation, ``feasible``, distances, objects, settled poses; ``pair`` ids do not match a
    world's, so no example pictures (``examples_per_action`` 0). Reused when there."""
    import numpy as np

    from relaff_jax.config.dataset import DatasetConfig
    from relaff_jax.constants import ACTIONS, RELATIONS
    from relaff_jax.data import generate_dataset, info

    sizes = DatasetConfig(n_samples=n, rollout_batch=4096)

    def rollout(key, batch):
        rng = np.random.default_rng(int(np.asarray(key).astype(np.int64).sum()))
        rel = rng.choice(3, batch, p=[0.47, 0.34, 0.19])
        feasible = rng.random(batch) < 0.7
        # ~6.7 % positive: ~75,000 rollouts per 10,000 samples, about the paper run's (700,000 in all)
        label = feasible & (rng.random(batch) < np.array([0.0, 0.17, 0.19])[rel])
        return {"qpos_settled": rng.normal(size=(batch, 21)).astype(np.float32), "rollout_id": rng.integers(0, 2**62, batch),"label": label, "relation": np.asarray(RELATIONS)[rel], "feasible": feasible,
                "cog_distance": np.abs(rng.normal(0.1 + 0.1 * (rel == 0), 0.05, batch)),
                "toy": rng.choice(["ball", "cube", "cup"], batch), "other": rng.choice(["plate", "box", "bowl"], batch),
                "pair": rng.integers(0, 40, batch)}

    dirs = {}
    for i, act in enumerate(ACTIONS):
        d = root / "data" / act
        try:
            done = info(d)["status"] == "complete"
        except Exception:  # noqa: BLE001 (absent or partial: write it)
            done = False
        if not done:
            generate_dataset(d, act, rollout, seed=i, progress=False, dataset_config=sizes)
        dirs[act] = str(d)
    return dirs


class Timers:
    """Inclusive and exclusive seconds per part (a stack: a part's time inside another's is
    taken off that one's exclusive time)."""

    def __init__(self):
        self.incl, self.excl, self.cpu, self.calls, self.stack = {}, {}, {}, {}, []

    def wrap(self, name, f):
        def timed(*a, **k):
            self.stack.append(0.0)
            t, c = time.perf_counter(), time.process_time()
            try:
                return f(*a, **k)
            finally:
                dt = time.perf_counter() - t
                self.cpu[name] = self.cpu.get(name, 0.0) + time.process_time() - c
                inner = self.stack.pop()
                if self.stack:
                    self.stack[-1] += dt
                self.incl[name] = self.incl.get(name, 0.0) + dt
                self.excl[name] = self.excl.get(name, 0.0) + dt - inner
                self.calls[name] = self.calls.get(name, 0) + 1
        return timed


def child(results: Path, report: Path, variant: str, profile: bool, data: dict | None, examples: int = 0) -> None:
    """One variant's report under the timers; prints one JSON line of its parts."""
    import importlib

    timers = Timers()
    t0 = time.perf_counter()
    import relaff_jax.report.write as W  # noqa: F401 (imports timed apart)
    t_import = time.perf_counter() - t0
    for mod, attr, name in PARTS:
        m = importlib.import_module(mod)
        setattr(m, attr, timers.wrap(name, getattr(m, attr)))
    kw = {"reference": True} if variant == "reference" else {}
    kw["data_dirs"] = data
    t, cpu = time.perf_counter(), time.process_time()
    if profile:
        import cProfile
        pr = cProfile.Profile()
        pr.runcall(W.write_report, results, report, examples_per_action=examples, **kw)
        pr.dump_stats(str(report) + ".prof")
    else:
        W.write_report(results, report, examples_per_action=examples, **kw)
    total, cpu = time.perf_counter() - t, time.process_time() - cpu
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB -> GB
    print(json.dumps({"variant": variant, "total": total, "cpu": cpu, "import": t_import, "rss_gb": rss,
                      "incl": timers.incl, "excl": timers.excl, "cpu_incl": timers.cpu, "calls": timers.calls}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/relaff_report_bench"))
    ap.add_argument("--sizes", type=int, default=99, help="training sizes 2, 3, ... (paper: 99)")
    ap.add_argument("--resamples", type=int, default=1000, help="bootstrap resamples (paper: 1000)")
    ap.add_argument("--variants", nargs="+", default=["reference", "new"], choices=["reference", "base", "new"])
    ap.add_argument("--base", type=Path, help="variant 'base': the default path of this checkout of the code "
                                              "(e.g. `git archive b38f728`, the fast path before issue 26's report work)")
    ap.add_argument("--profile", action="store_true", help="cProfile each variant (report.prof)")
    ap.add_argument("--data", type=int, default=0, metavar="N",
                    help="also the --data sections, on nine datasets of N samples (paper: 10000; built once)")
    ap.add_argument("--run", type=Path, help="a finished `relaff reproduce` folder (its results and datasets) "
                                             "instead of the synthetic one; nothing projected")
    ap.add_argument("--examples", type=int, default=2, help="with --run: example scenes per action (the stage's default 2)")
    ap.add_argument("--child", nargs=2, metavar=("VARIANT", "REPORT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.run:
        results = args.run / "results"
        data = {a: str(args.run / "data" / a) for a in _actions() if (args.run / "data" / a).is_dir()} or None
    else:
        results = args.out / "results"
        data = {a: str(args.out / "data" / a) for a in _actions()} if args.data else None
    if args.child:
        return child(results, Path(args.child[1]), args.child[0], args.profile, data, args.examples if args.run else 0)
    print(f"{platform.machine()} {os.cpu_count()} cores, load average {os.getloadavg()}")
    if not args.run:
        build(args.out, args.sizes, args.resamples)
    if args.data and not args.run:
        t = time.perf_counter()
        build_data(args.out, args.data)
        print(f"datasets ready in {time.perf_counter() - t:.0f} s")
    runs = {}
    for v in args.variants:
        report = args.out / f"report_{v}"
        cmd = [sys.executable, __file__, "--out", str(args.out), "--child", v, str(report), "--data", str(args.data)]
        cmd += ["--run", str(args.run), "--examples", str(args.examples)] if args.run else []
        cmd += ["--profile"] if args.profile else []
        code = args.base if v == "base" else HERE
        p = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(code)))
        if p.returncode:
            sys.exit(p.stderr)
        runs[v] = json.loads(p.stdout.strip().splitlines()[-1])
    scale = 1.0 if args.run else 99 / args.sizes  # see the module docstring
    names = [n for _, _, n in PARTS if any(n in r["incl"] for r in runs.values())]
    head = f"{'part':26}" + "".join(f" {v + ' incl':>14} {v + ' excl':>14} {v + ' CPU':>14}" for v in runs)
    print(f"{results}: seconds" if args.run else
          f"{args.sizes} sizes, {args.resamples} resamples; seconds (projection x{scale:.2f} to 99 sizes in the last line)")
    print(head)
    for n in names:
        print(f"{n:26}" + "".join(f" {r['incl'].get(n, 0):14.2f} {r['excl'].get(n, 0):14.2f} {r['cpu_incl'].get(n, 0):14.2f}"
                                  for r in runs.values()))
    for key in ("total", "cpu", "import"):
        print(f"{key:26}" + "".join(f" {r[key]:14.2f} {'':14} {'':14}" for r in runs.values()))
    print(f"{'peak RSS GB':26}" + "".join(f" {r['rss_gb']:14.2f} {'':14}" for r in runs.values()))
    if not args.run:
        print(f"{'projected total (paper)':26}" + "".join(f" {_project(r, scale):14.0f} {'':14}" for r in runs.values()))
    first = next(iter(runs))
    for v in list(runs)[1:]:
        same = {f: _same(args.out / f"report_{first}" / f, args.out / f"report_{v}" / f) for f in COMPARED}
        print(f"{v} files identical to {first}'s: {same}")
        print(f"ratio {first}/{v} total {runs[first]['total'] / runs[v]['total']:.2f}, CPU {runs[first]['cpu'] / runs[v]['cpu']:.2f}"
              + ("" if args.run else f"; projected to the paper preset {_project(runs[first], scale):.0f} s -> "
                 f"{_project(runs[v], scale):.0f} s"))


def _project(run: dict, scale: float) -> float:
    """The paper preset's seconds: the dataset sections as measured (they do not grow with the
    sizes), everything else times 99 / sizes."""
    data = sum(t for n, t in run["incl"].items() if n.startswith("data:"))
    return (run["total"] - data) * scale + data


def _actions() -> tuple:
    from relaff_jax.constants import ACTIONS

    return ACTIONS


def _same(a: Path, b: Path) -> bool | None:
    if not a.exists() and not b.exists():
        return None
    return a.exists() and b.exists() and a.read_bytes() == b.read_bytes()


if __name__ == "__main__":
    main()
