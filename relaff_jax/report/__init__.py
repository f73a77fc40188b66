"""Reports: Table II, findings, figures and the report document of an experiment folder.

``write_report(RESULTS, REPORT, data_dirs=None, info=None, examples_per_action=2)`` is the one
writer (``relaff report``, ``relaff reproduce``): one analysis, then every output from it.

Files:

- ``write.py``: ``write_report``;
- ``tables.py``: Table II as CSV and Markdown, ``summary.json``;
- ``findings.py``: which of the paper's findings a run reproduces; correlation clusters;
- ``figures.py``: paper Figs. 6-12 and the dataset figure (``matplotlib.figure.Figure``, no pyplot);
- ``examples.py``: example scenes drawn by ``relaff_jax.perception.from_sim.show_scene``;
- ``sections.py``: the document's sections as blocks;
- ``document.py``: blocks rendered as ``report.md`` and a self-contained ``report.html``;
- ``formatting.py``: number formatting shared by the above.
"""
from relaff_jax.report.document import render_html, render_markdown
from relaff_jax.report.figures import dataset_figure, write_figures
from relaff_jax.report.findings import (
    VERDICTS,
    FindingRules,
    combine,
    correlation_clusters,
    findings,
    judge,
    verdict,
)
from relaff_jax.report.formatting import finite, fmt
from relaff_jax.report.tables import CSV_COLUMNS, summary, table2_csv, table2_markdown
from relaff_jax.report.write import write_report

__all__ = [
    "CSV_COLUMNS", "FindingRules", "correlation_clusters", "dataset_figure", "findings", "finite", "fmt",
    "render_html", "render_markdown", "summary", "table2_csv", "table2_markdown", "verdict", "write_figures", "VERDICTS", "combine", "judge",
    "write_report",
]
