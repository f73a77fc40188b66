"""Stage 4, ``report``: Table II beside the paper's, findings, figures and example scenes
(``relaff_jax.report.write.write_report``), in ``DIR/report/``.

``report_folder(tree, results, out, data_dirs=...)`` writes the report of one experiment
folder, its config record and, last, the inputs' stamp (``report.status``), so a killed writer
leaves a report without a stamp: what ``relaff report`` calls, and what ``run(run, forced)``
calls with the run folder's results and datasets and the run log. The report's shape comes
from ``tree.reproduce.examples_per_action`` and ``tree.reproduce.spaces`` only. ``report``
keeps the computation.
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Mapping

from relaff_jax import io as rio
from relaff_jax.errors import UserError
from relaff_jax.stages.protocol import Run, Status
from relaff_jax.data.audit import AUDIT_FILE, DEFAULT_SAMPLE, stored_audit
from relaff_jax.data.layout import FEATURES_SIDECAR, SIDECAR
from relaff_jax.learn import folder as L
from relaff_jax.report.status import clear_stamp, inputs_stamp, report_status, write_stamp
from relaff_jax.io import check_writable_dir
from relaff_jax.provenance import record_config
from relaff_jax.stages.generate import audit_one
from relaff_jax.report import folder as R

NAME = "report"
COMMAND = "report"  # the command the folder's config record names


def inputs(tree: Any, results: str | os.PathLike, data_dirs: Mapping[str, str | os.PathLike] | None = None) -> list[Path]:
    """The files a report of ``results`` (and the datasets ``data_dirs``) is made from."""
    files = [L.meta(results)] + [L.results(results, s) for s in tree.reproduce.spaces]
    for d in (data_dirs or {}).values():
        files += [Path(d) / SIDECAR, Path(d) / FEATURES_SIDECAR]
        # the physics audit shown beside the labels, once there is one: a run folder from before
        # the audit keeps its stamp (its report stays complete; `--force report` adds the audits)
        files += [Path(d) / AUDIT_FILE] if (Path(d) / AUDIT_FILE).is_file() else []
    return files


def stamp(tree: Any, results: str | os.PathLike, data_dirs: Mapping[str, str | os.PathLike] | None = None) -> dict:
    """The stamp of a report of ``results`` made with ``tree``'s settings (``report.status.inputs_stamp``)."""
    return inputs_stamp(inputs(tree, results, data_dirs), {"examples_per_action": tree.reproduce.examples_per_action})


def report_folder(tree: Any, results: str | os.PathLike, out: str | os.PathLike, *,
                  data_dirs: Mapping[str, str | os.PathLike] | None = None,
                  info: Mapping[str, Any] | None = None) -> Path:
    """Write the report of the experiment folder ``results`` into ``out``; return ``out``.

    tree: a ``RunConfig`` (``reproduce.examples_per_action`` example scenes per action when
      ``data_dirs`` are given). data_dirs: ``{action: DIR}`` of the datasets the experiment
      learnt from (their statistics, figures and example scenes). info: the run log of
      ``relaff reproduce`` (``preset``, ``seed``, ``timings``, ``versions``).
    A folder that is not an experiment folder and an ``out`` that cannot be written are
    ``UserError``s raised before anything is read.
    """
    if not L.meta(results).is_file():
        raise UserError(f"{results} is not an experiment folder (no {L.META})")
    check_writable_dir(Path(out), "--out")
    # loaded when the stage runs: reproduce --status and the command's checks read this module
    from relaff_jax.report.write import write_report

    clear_stamp(out)
    write_report(results, out, data_dirs=data_dirs, info=info,
                 examples_per_action=tree.reproduce.examples_per_action)
    record_config(out, tree, COMMAND)
    write_stamp(out, stamp(tree, results, data_dirs))
    return Path(out)


def _data_dirs(run: Run) -> dict[str, Path]:
    return {a: run.paths.dataset(a) for a in run.cfg.reproduce.actions}


def status(run: Run) -> Status:
    return Status(*report_status(run.paths.report, stamp(run.cfg, run.paths.results, _data_dirs(run))))


def progress(run: Run) -> float:
    return 0.0


def _audits(run: Run) -> None:
    """Every dataset's physics audit (``generate.audit_one``): stored ones are reused, a run
    whose datasets predate the audit gets them here (one that cannot be replayed is said so at
    once, ``generate.audit_one``)."""
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
    report_folder(run.cfg, run.paths.results, out, data_dirs=_data_dirs(run), info=info)
    dt = time.perf_counter() - t0
    run.progress.message(f"report: {R.html(out)} in {dt:.0f} s")
    return {"status": "ran", "seconds": round(dt, 2)}
