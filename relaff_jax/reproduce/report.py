"""Stage 4, ``report``: Table II beside the paper's, findings, figures and example scenes
(``relaff_jax.report.run``, what ``relaff report`` runs), in ``DIR/report/``."""
from __future__ import annotations

import time
from pathlib import Path

from relaff_jax import io as rio
from relaff_jax import report
from relaff_jax.report import folder as R
from relaff_jax.report.status import report_status
from relaff_jax.reproduce.stage import Run, Status

NAME = "report"


def _data_dirs(run: Run) -> dict[str, Path]:
    return {a: run.paths.dataset(a) for a in run.cfg.reproduce.actions}


def stamp(run: Run) -> dict:
    return report.stamp(run.cfg, run.paths.results, _data_dirs(run))


def status(run: Run) -> Status:
    return Status(*report_status(run.paths.report, stamp(run)))


def progress(run: Run) -> float:
    return 0.0


def _audits(run: Run) -> None:
    """Every dataset's physics audit (``generate.audit_one``): stored ones are reused, a run
    whose datasets predate the audit gets them here (one that cannot be replayed is said so at
    once, ``generate.audit_one``)."""
    from relaff_jax.data.audit import DEFAULT_SAMPLE, stored_audit
    from relaff_jax.reproduce.generate import audit_one

    todo = [a for a, d in _data_dirs(run).items() if stored_audit(d, DEFAULT_SAMPLE, 0) is None]
    for k, action in enumerate(todo):
        run.progress.set(f"physics audit of {action} ({k + 1}/{len(todo)})")
        audit_one(run, action)


def run(run: Run, forced: bool) -> dict:
    out = run.paths.report
    if forced:
        rio.remove_tree(out)
    t0 = time.perf_counter()
    _audits(run)
    run.progress.set("tables, figures, example scenes")
    info = {"preset": run.preset, "seed": run.seed, "versions": run.log["versions"],
            "timings": {s: round(t, 1) for s, t in run.log["timings"].items()}}
    report.run(run.cfg, run.paths.results, out, data_dirs=_data_dirs(run), info=info)
    dt = time.perf_counter() - t0
    run.progress.message(f"report: {R.html(out)} in {dt:.0f} s")
    return {"status": "ran", "seconds": round(dt, 2)}
