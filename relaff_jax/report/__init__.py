"""Reports: Table II, findings, figures and the report document of an experiment folder.

``write_report(RESULTS, REPORT, ...)`` is the one writer (one analysis, then every output from
it); the stage over the whole config tree (``relaff report``, ``relaff reproduce``: the writer,
then the config record and the inputs' stamp) is ``relaff_jax.stages.report``.

Files:

- ``folder.py``: the report folder's file names (``report.md``, ``summary.json``, ``fig*.png``, ...);
- ``write.py``: ``write_report``;
- ``tables.py``: Table II as CSV and Markdown, ``summary.json``;
- ``findings.py``: which of the paper's findings a run reproduces; correlation clusters;
- ``figures.py``: paper Figs. 6-12 and the dataset figure (``matplotlib.figure.Figure``, no pyplot);
- ``examples.py``: example scenes drawn by ``relaff_jax.perception.from_sim.show_scene``;
- ``sections.py``: the document's sections as blocks (re-exporting the two below);
- ``data_sections.py``: the datasets' statistics and the example scenes;
- ``run_sections.py``: the introduction, the sizes of the protocol and the run;
- ``document.py``: blocks rendered as ``report.md`` and a self-contained ``report.html``;
- ``reach.py``: the "Reach or relation" section (what the labels consist of, ``reach.json``);
- ``audit.py``: the "Physics audit" section from the datasets' stored audits (``fig_audit.png``);
- ``borrow.py``: what one source can lend each affordance (DB1's bootstrap factor beside the
  strongest correlation of its predictor with another action's);
- ``robustness.py``: each finding in every reading (the robustness table);
- ``readings.py``: ``relaff compare``, several report folders side by side;
- ``status.py``: the inputs' stamp of a report folder (its status for ``relaff reproduce``);
- ``formatting.py``: number formatting shared by the above.
"""
from relaff_jax.report.document import render_html, render_markdown
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

# Not re-exported: the figures (``figures.dataset_figure``, ``write_figures``: matplotlib) and the
# writer (``write.write_report``: the learning stage's results, JAX), so that ``relaff report`` and
# ``relaff reproduce --status`` (``report.status``) check their inputs before those imports run.

__all__ = [
    "CSV_COLUMNS", "FindingRules", "correlation_clusters", "findings", "finite", "fmt",
    "render_html", "render_markdown", "summary", "table2_csv", "table2_markdown", "verdict", "VERDICTS", "combine", "judge",
]
