"""Stage 4, ``report``: Table II beside the paper's, findings, figures and example scenes
(``relaff_jax.report.write_report``), in ``DIR/report/``."""
from __future__ import annotations

import time
from pathlib import Path

from relaff_jax import data as D
from relaff_jax import io as rio
from relaff_jax.learn import folder as L
from relaff_jax.report.status import clear_stamp, inputs_stamp, report_status, write_stamp
from relaff_jax.reproduce.stage import Run, Status

NAME = "report"


def _inputs(run: Run) -> list[Path]:
    res = run.paths.results
    files = [L.meta(res)] + [L.results(res, s) for s in run.cfg.reproduce.spaces]
    for a in run.cfg.reproduce.actions:
        files += [run.paths.dataset(a) / D.SIDECAR, run.paths.dataset(a) / D.FEATURES_SIDECAR]
    return files


def stamp(run: Run) -> dict:
    return inputs_stamp(_inputs(run), {"examples_per_action": run.cfg.reproduce.examples_per_action})


def status(run: Run) -> Status:
    return Status(*report_status(run.paths.report, stamp(run)))


def progress(run: Run) -> float:
    return 0.0


def run(run: Run, forced: bool) -> dict:
    from relaff_jax.report import write_report

    out = run.paths.report
    if forced:
        rio.remove_tree(out)
    clear_stamp(out)
    run.progress.set("tables, figures, example scenes")
    t0 = time.perf_counter()
    info = {"preset": run.preset, "seed": run.seed, "versions": run.log["versions"],
            "timings": {s: round(t, 1) for s, t in run.log["timings"].items()}}
    write_report(run.paths.results, out, data_dirs={a: run.paths.dataset(a) for a in run.cfg.reproduce.actions},
                 info=info, examples_per_action=run.cfg.reproduce.examples_per_action)
    write_stamp(out, stamp(run))
    dt = time.perf_counter() - t0
    run.progress.message(f"report: {out / 'report.html'} in {dt:.0f} s")
    return {"status": "ran", "seconds": round(dt, 2)}
