"""The report folder's layout, named once (``relaff report --out``, ``DIR/report``)::

    OUT/table2.csv, table2_rhf.csv, table2.md   Table II beside the paper's (``tables.py``)
    OUT/affordances.csv                         per affordance: does DB1 help it (``affordances.py``)
    OUT/summary.json                            Table II per space, the figures' names
    OUT/findings.json                           every finding's verdict (``findings.py``)
    OUT/reach.json                              what the labels consist of (``reach.py``)
    OUT/fig06_nb_learning.png ... fig12_thresholds.png   paper Figs. 6-12 (``figures.py``)
    OUT/fig_datasets.png, fig_reach.png         the datasets' figures (with datasets)
    OUT/fig_audit.png                           the datasets' physics audits (``audit.py``)
    OUT/examples/ACTION_IIIII.png               example scenes (``examples.py``)
    OUT/report.md, report.html                  the document (``document.py``)
    OUT/relaff_config.json                      the config record (``stage.py``)
    OUT/report_stamp.json                       the inputs' stamp, written last (``status.py``)
"""
from __future__ import annotations

import os
from pathlib import Path

TABLE2_CSV = "table2.csv"
TABLE2_RHF_CSV = "table2_rhf.csv"
TABLE2_MD = "table2.md"
AFFORDANCES_CSV = "affordances.csv"
SUMMARY = "summary.json"
FINDINGS = "findings.json"
REACH = "reach.json"
MARKDOWN = "report.md"
HTML = "report.html"
STAMP = "report_stamp.json"
EXAMPLES = "examples"

FIG_NB_LEARNING = "fig06_nb_learning.png"
FIG_NB_SPACES = "fig07_nb_spaces.png"
FIG_DB1_BEST = "fig08_db1_best.png"
FIG_DB1_BEST_BF = "fig09_db1_best_bf.png"
FIG_AVERAGE_BF = "fig10_average_bf.png"
FIG_CORRELATION = "fig11_correlation.png"
FIG_THRESHOLDS = "fig12_thresholds.png"
FIG_DATASETS = "fig_datasets.png"
FIG_REACH = "fig_reach.png"
FIG_AUDIT = "fig_audit.png"

JSON_FILES = (SUMMARY, FINDINGS, REACH)  # what ``readings.compare_readings`` reads
REQUIRED = (MARKDOWN, HTML, SUMMARY)  # a whole report has these and its stamp


def example(action: str, index: int) -> str:
    """An example scene's file name under ``EXAMPLES``."""
    return f"{action}_{index:05d}.png"


def html(out: str | os.PathLike) -> Path:
    return Path(out) / HTML
