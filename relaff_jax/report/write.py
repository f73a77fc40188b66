"""The one report writer: an experiment folder (and optionally its datasets) to a report folder.

Takes ``RESULTS`` written by ``relaff experiment`` (``experiment.json`` + ``<space>/results.npz``),
optionally the dataset folders ``{action: DIR}`` and a run log; analyses every space once
(``relaff_jax.learn.analyse``) and writes, from that one analysis, to ``REPORT``:

* ``affordances.csv``: per space and affordance whether DB1 helps it (``affordances.py``);
* ``table2.csv`` (PCA, beside the paper's), ``table2_rhf.csv`` when RHF was run, ``table2.md``
  and ``summary.json`` (``tables.py``);
* ``fig06_nb_learning.png`` ... ``fig12_thresholds.png`` (``figures.py``);
* ``findings.json`` (``findings.py``);
* with datasets: ``fig_datasets.png``, ``fig_reach.png``, ``reach.json`` (what the labels
  consist of, ``reach.py``), ``fig_audit.png`` (their stored physics audits, ``audit.py``) and
  ``examples/*.png`` (``examples.py``, drawn in a second process meanwhile);
* ``report.md`` and the self-contained ``report.html`` (``sections.py``, ``document.py``).
"""
from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path
from typing import Any, Mapping

from relaff_jax import io as rio
from relaff_jax import provenance
from relaff_jax.learn import analyse
from relaff_jax.learn.results import load_results
from relaff_jax.learn.user_rows import user_rows
from relaff_jax.report import folder as F
from relaff_jax.report.affordances import blocks as affordance_blocks, csv_text as affordance_csv
from relaff_jax.report.audit import audit_blocks, stored_audits
from relaff_jax.report import sections as S
from relaff_jax.report.document import render_html, render_markdown
from relaff_jax.report.examples import examples_beside
from relaff_jax.report.figures import dataset_figure, write_figures
from relaff_jax.report.findings import FindingRules, findings
from relaff_jax.report.robustness import by_reading
from relaff_jax.report.formatting import finite
from relaff_jax.report.borrow import borrow_blocks, borrow_rows
from relaff_jax.report.reach import predictor_blocks, reach_blocks, reach_figure, reach_json, subset_blocks
from relaff_jax.report.tables import summary, table2_csv, table2_markdown
from relaff_jax.data import DatasetError, anatomy
from relaff_jax.data import info as dataset_info


def _load() -> tuple[float, float, float] | None:
    try:
        return os.getloadavg()
    except OSError:  # not available on this platform
        return None


def write_report(results_dir: str | os.PathLike, out_dir: str | os.PathLike,
                 data_dirs: Mapping[str, str | os.PathLike] | None = None,
                 info: Mapping[str, Any] | None = None, examples_per_action: int = 2,
                 rules: FindingRules = FindingRules(), reference: bool = False) -> Path:
    """Write the report of ``results_dir`` to ``out_dir``; return ``out_dir``.

    data_dirs: ``{action: DIR}`` of the datasets the experiment learnt from; adds their
      statistics, ``fig_datasets.png`` and ``examples_per_action`` example scenes per action.
    info: the run log of ``relaff reproduce`` (``preset``, ``seed``, ``timings``, ``versions``).
    rules: how the findings summary decides whether a paper finding is reproduced.
    reference: the reference paths of the analysis and the writer (the same files, slower;
      kept to check the default ones against).
    """
    t0 = time.perf_counter()
    infos: dict[str, Any] = {}
    anat: dict[str, Any] = {}
    missing: dict[str, str] = {}
    if data_dirs:  # every input read before the first file is written: a damaged dataset writes nothing
        infos = {act: dataset_info(d) for act, d in data_dirs.items()}
        for act, d in data_dirs.items():
            try:
                anat[act] = anatomy(d)
            except DatasetError as e:  # e.g. rollouts without a 'feasible' field
                missing[act] = str(e)
    res = load_results(results_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # the example scenes, drawn in a process of their own while the rest is made here
    examples = examples_beside(data_dirs, out / F.EXAMPLES, examples_per_action) if data_dirs else None
    try:
        return _document(results_dir, res, out, data_dirs, infos, anat, missing, examples, info, rules, reference, t0)
    except BaseException:
        if examples is not None:
            examples.cancel()  # a failed or stopped report does not wait for its pictures
        raise


def _document(results_dir, res, out: Path, data_dirs, infos: dict, anat: dict, missing: dict, examples, info,
              rules: FindingRules, reference: bool, t0: float) -> Path:
    """``write_report`` once its inputs are read: analyses, tables, figures and the document."""
    cfg = res["config"]
    spaces = list(res["meta"]["spaces"])
    an = {s: analyse(res[s], cfg, seed=int(res["meta"]["seed"]), reference=reference) for s in spaces}
    for s in spaces:  # a user's registered conditions, beside Table II's rows (none: empty)
        an[s]["user"] = user_rows(res[s], cfg, seed=int(res["meta"]["seed"]), reference=reference)
    main = "pca" if "pca" in an else spaces[0]

    # tables, figures and the summary
    rio.atomic_write_text(out / F.TABLE2_CSV, table2_csv(an[main], paper=main == "pca"))
    if main == "pca" and "rhf" in an:
        rio.atomic_write_text(out / F.TABLE2_RHF_CSV, table2_csv(an["rhf"], paper=False))
    rio.atomic_write_text(out / F.TABLE2_MD, table2_markdown(res, an))
    rio.atomic_write_text(out / F.AFFORDANCES_CSV, affordance_csv(an))
    figs = write_figures(res, an, out)
    lend = {s: borrow_rows(res[s], an[s], cfg) for s in spaces}
    rio.atomic_write_json(out / F.SUMMARY, summary(res, an, [p.name for p in figs]) | {"borrow": finite(lend)})

    # datasets and example scenes
    data_blocks: list[tuple] = []
    n_samples = None
    if data_dirs:
        n_samples = {act: i["n"] for act, i in infos.items()}
        dataset_figure(infos, out / F.FIG_DATASETS)
        data_blocks = S.dataset_blocks(infos, F.FIG_DATASETS)
        if anat:
            reach_figure(anat, out / F.FIG_REACH)
        data_blocks += reach_blocks(anat, missing, out) + subset_blocks(res, cfg) + predictor_blocks(res)
        data_blocks += audit_blocks(*stored_audits(data_dirs), out)
        data_blocks += S.example_blocks(examples())
    rio.atomic_write_json(out / F.REACH, finite(reach_json(anat, res, cfg)))

    # the document
    found = findings(an, cfg, rules)
    readings = by_reading(an, cfg, rules)  # the analysis-only readings of the same results
    top = S.findings_blocks(found)
    top[1:1] = S.scale_caveat_blocks(an[main], (info or {}).get("preset"))  # beside the verdicts, not pages later
    blocks = (S.intro_blocks(res, results_dir, info) + top + S.robustness_blocks(readings, cfg)
              + S.protocol_blocks(res, an, cfg, n_samples) + data_blocks
              + S.learning_blocks(out, main) + S.table2_blocks(an, cfg, out, (info or {}).get("preset"))
              + affordance_blocks(an, cfg)
              + [b for s in spaces for b in S.methods_blocks(an[s], cfg, s)]
              + [b for s in spaces for b in borrow_blocks(lend[s], s)] + S.best_after_ten_blocks(an[main], cfg, main)
              + S.correlation_blocks(res, an, cfg, out) + S.threshold_blocks(res[main]["corr"], an[main], cfg, main, out)
              + S.run_blocks(info, time.perf_counter() - t0, _load(), provenance.machine()))
    rio.atomic_write_json(out / F.FINDINGS, finite({"findings": found, "rules": dataclasses.asdict(rules),
                                                    "readings": readings}))
    rio.atomic_write_text(out / F.MARKDOWN, render_markdown(blocks))
    rio.atomic_write_text(out / F.HTML, render_html(blocks, out, "relaff_jax reproduction report"))
    return out
