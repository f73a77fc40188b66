"""The report stage's one entry point: ``run(tree, results, out, ...)``, what ``relaff report``
and ``relaff reproduce`` both call.

Takes the whole config tree (``runconfig.RunConfig``: ``reproduce.examples_per_action`` and
``reproduce.spaces`` shape the report and its stamp), a finished experiment folder, the report
folder and optionally the datasets and the run log; checks the inputs before any work, writes
the report (``write.write_report``), the config record (``provenance.record_config``, command
``"report"``) and, last, the inputs' stamp (``status.py``), so a killed writer leaves a report
without a stamp. Returns the report folder.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

from relaff_jax.errors import UserError

COMMAND = "report"


def inputs(tree: Any, results: str | os.PathLike, data_dirs: Mapping[str, str | os.PathLike] | None = None) -> list[Path]:
    """The files a report of ``results`` (and the datasets ``data_dirs``) is made from."""
    from relaff_jax.data.layout import FEATURES_SIDECAR, SIDECAR
    from relaff_jax.learn import folder as L

    from relaff_jax.data.audit import AUDIT_FILE

    files = [L.meta(results)] + [L.results(results, s) for s in tree.reproduce.spaces]
    for d in (data_dirs or {}).values():
        files += [Path(d) / SIDECAR, Path(d) / FEATURES_SIDECAR]
        # the physics audit shown beside the labels, once there is one: a run folder from before
        # the audit keeps its stamp (its report stays complete; `--force report` adds the audits)
        files += [Path(d) / AUDIT_FILE] if (Path(d) / AUDIT_FILE).is_file() else []
    return files


def stamp(tree: Any, results: str | os.PathLike, data_dirs: Mapping[str, str | os.PathLike] | None = None) -> dict:
    """The stamp of a report of ``results`` made with ``tree``'s settings (``status.inputs_stamp``)."""
    from relaff_jax.report.status import inputs_stamp

    return inputs_stamp(inputs(tree, results, data_dirs), {"examples_per_action": tree.reproduce.examples_per_action})


def run(tree: Any, results: str | os.PathLike, out: str | os.PathLike, *,
        data_dirs: Mapping[str, str | os.PathLike] | None = None, info: Mapping[str, Any] | None = None) -> Path:
    """Write the report of the experiment folder ``results`` into ``out``; return ``out``.

    tree: a ``RunConfig`` (``reproduce.examples_per_action`` example scenes per action when
      ``data_dirs`` are given). data_dirs: ``{action: DIR}`` of the datasets the experiment
      learnt from (their statistics, figures and example scenes). info: the run log of
      ``relaff reproduce`` (``preset``, ``seed``, ``timings``, ``versions``).
    A folder that is not an experiment folder and an ``out`` that cannot be written are
    ``UserError``s raised before anything is read.
    """
    from relaff_jax.io import check_writable_dir
    from relaff_jax.learn import folder as L

    if not L.meta(results).is_file():
        raise UserError(f"{results} is not an experiment folder (no {L.META})")
    check_writable_dir(Path(out), "--out")
    from relaff_jax.provenance import record_config
    from relaff_jax.report.status import clear_stamp, write_stamp
    from relaff_jax.report.write import write_report

    clear_stamp(out)
    write_report(results, out, data_dirs=data_dirs, info=info,
                 examples_per_action=tree.reproduce.examples_per_action)
    record_config(out, tree, COMMAND)
    write_stamp(out, stamp(tree, results, data_dirs))
    return Path(out)
