"""The report's blocks about the run: the introduction (where the results came from), the
sizes of the protocol beside the paper's, and the run itself (preset, timings, machine,
versions); ``sections`` re-exports them."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Mapping

from relaff_jax.learn import pool_sizes
from relaff_jax.report.formatting import span


def intro_blocks(res: Mapping[str, Any], results_dir: str | Path, run_info: Mapping[str, Any] | None) -> list[tuple]:
    cfg = res["config"]
    spaces = list(res["meta"]["spaces"])
    blocks: list[tuple] = [("h", 1, "Bootstrapping relational affordances: reproduction report")]
    intro = (f"Generated {time.strftime('%Y-%m-%d %H:%M')} from `{Path(results_dir)}`: actions {', '.join(res['meta']['actions'])}; "
             f"spaces {', '.join(s.upper() for s in spaces)}; seed {res['meta']['seed']}; training sizes "
             f"{', '.join(map(str, cfg.sizes)) if len(cfg.sizes) <= 12 else f'{min(cfg.sizes)}..{max(cfg.sizes)}'}; "
             f"repetitions PCA {cfg.reps_pca}, RHF {cfg.reps_rhf}.")
    if run_info:
        intro += f" Preset `{run_info.get('preset')}`."
    blocks += [("p", intro)]
    if any(str(d).startswith("synthetic") for d in res["meta"].get("data", [])):
        blocks.append(("p", "**These results come from synthetic features** (`relaff experiment --synthetic`): they test "
                            "the pipeline and say nothing about the paper."))
    return blocks


PAPER_SIZES = {"source": 2000, "category": 2000, "corr": 500, "test": 4000, "reps": "50 (PCA) / 25 (RHF)",
               "sizes": "2..100 (99 sizes)"}


def protocol_blocks(res: Mapping[str, Any], an: Mapping[str, Mapping[str, Any]], cfg: Any,
                    n_samples: Mapping[str, int] | None = None) -> list[tuple]:
    """The size of every part of the protocol beside the paper's (``n_samples``: samples per
    action, for the pools a preset shrinks to the data)."""
    def rng(vals) -> str:
        vals = [int(v) for v in vals]
        return f"{min(vals)}" if min(vals) == max(vals) else f"{min(vals)}-{max(vals)}"

    recorded = res["meta"].get("pool_sizes")  # written by the sweep
    if recorded:
        src, corr = rng(p["source"] for p in recorded.values()), rng(p["corr"] for p in recorded.values())
    elif n_samples:
        pools = [pool_sizes(int(n), cfg) for n in n_samples.values()]
        src, corr = rng(p[0] for p in pools), rng(p[1] for p in pools)
    else:
        shrunk = " (or fewer: shrunk to the data)" if cfg.shrink_to_data else ""
        src, corr = f"{cfg.source_size}{shrunk}", f"{cfg.corr_scenes}{shrunk}"
    tests = [int(v) for x in an.values() if x.get("test_size") is not None for v in x["test_size"]]
    k = len(res["meta"]["actions"])
    rows = [["source predictors (training samples each)", src, PAPER_SIZES["source"]],
            ["category sets (samples per half of a category)", src, PAPER_SIZES["category"]],
            [f"correlation scenes (per action, shown to all {k} predictors)", corr, PAPER_SIZES["corr"]],
            ["test scenes (per affordance)", rng(tests) if tests else str(cfg.test_size), PAPER_SIZES["test"]],
            ["repetitions", f"{cfg.reps_pca} (PCA) / {cfg.reps_rhf} (RHF)", PAPER_SIZES["reps"]],
            ["training sizes n", f"{min(cfg.sizes)}..{max(cfg.sizes)} ({len(cfg.sizes)} sizes)", PAPER_SIZES["sizes"]],
            ["window of the average bf", f"n = {span(cfg.sizes, *cfg.bf_sizes)}", "n = 4..25"],
            ["bootstrap resamples of the intervals", cfg.ci_resamples, "- (no intervals)"]]
    return [("h", 2, "Sizes of the protocol"), ("table", ["part", "this run", "paper"], rows)]


def run_blocks(run_info: Mapping[str, Any] | None, report_s: float | None = None,
               load: tuple[float, float, float] | None = None, machine: Mapping[str, Any] | None = None) -> list[tuple]:
    """The run's preset, seed, stage times, machine, load and versions.

    report_s: seconds this report has taken up to its writing (the run log's own ``report``
      timing, when there, is of an earlier report); load: the 1/5/15-minute load averages
      as the report is written (a loaded machine makes every timing above slower).
    """
    info = dict(run_info or {})
    items = [f"preset `{info.get('preset')}`, seed {info.get('seed')}"] if run_info else []
    timings = dict(info.get("timings") or {})
    if report_s is not None:
        timings["report"] = f"{report_s:.0f} s (this document)"
    for st, t in timings.items():
        items.append(f"{st}: {t:.0f} s" if isinstance(t, (int, float)) else f"{st}: {t}")
    m = info.get("machine") or machine
    if m:
        isa = ", ".join(m.get("isa") or []) or "-"
        items.append(f"machine: {m.get('cpu_model')}, {m.get('cpus')} cores, {m.get('machine')} ({isa}); {m.get('platform')}")
        if m.get("blas"):  # the kernels the PCA features' eigen-solver ran on (older logs lack them)
            items.append("BLAS kernels: " + ", ".join(f"{b.get('internal_api')} {b.get('version')} {b.get('architecture')}"
                                                      for b in m["blas"]))
    if load is not None:
        items.append("load average as the report was written: " + " / ".join(f"{x:.2f}" for x in load)
                     + " (1 / 5 / 15 min)")
    v = info.get("versions") or {}
    if v:
        items.append("versions: " + ", ".join(f"{k} {val}" for k, val in v.items() if val))
    return [("h", 2, "The run"), ("ul", items)] if items else []
