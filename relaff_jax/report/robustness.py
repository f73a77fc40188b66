"""Each finding in every reading of the paper's open choices (issue 44; docs/learning.md, "The
paper's open choices").

Takes the findings of one run in each analysis-only reading (``by_reading``: the same results
re-read, e.g. ``after_ten=whole`` and ``after_ten=causal``) or of several runs that differ in a
fit-changing reading (``relaff compare NAME=REPORT ...``: their ``findings.json``), and gives
``robustness_rows``: per finding its verdict and the intervals of its claims in each reading and
whether it survives every reading (reproduced in all of them), and ``robustness_table``, the
table ``(header, rows)`` the report and ``relaff compare`` print.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping, Sequence

from relaff_jax.report.formatting import fmt
from relaff_jax.config.experiment import AFTER_TEN
from relaff_jax.report.findings import findings


def by_reading(an: Mapping[str, Any], cfg: Any, rules: Any) -> dict[str, list[dict[str, Any]]]:
    """``{"after_ten=R": findings}`` for every reading R of ``after_ten`` (no refit: the same
    analysis, only the rows the finding reads differ)."""
    return {f"after_ten={r}": findings(an, dataclasses.replace(cfg, after_ten=r), rules) for r in AFTER_TEN}


def claims_text(f: Mapping[str, Any], nd: int = 2) -> str:
    """A finding's claims as ``estimate [low, high]``, separated by ``;``."""
    out = []
    for c in f.get("claims") or []:
        lo, hi = (c.get("interval") or [None, None])[:2]
        out.append(f"{fmt(c.get('estimate'), nd)} [{fmt(lo, nd)}, {fmt(hi, nd)}]")
    return "; ".join(out) or "-"


def robustness_rows(readings: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[dict[str, Any]]:
    """Per finding (in the first reading's order): ``{id, finding, cells: {reading: (verdict,
    claims_text)}, survives}``; ``survives`` is "yes" where it is reproduced in every reading,
    "no: never" where in none, else "no: only in R1, R2" (a finding about the reading)."""
    names = list(readings)
    found = {n: {f["id"]: f for f in readings[n]} for n in names}
    rows = []
    for fid, f in found[names[0]].items():
        cells, held = {}, []
        for n in names:
            g = found[n].get(fid)
            cells[n] = ("-", "-") if g is None else (g["verdict"], claims_text(g))
            if g is not None and g["verdict"] == "reproduced":
                held.append(n)
        survives = "yes" if len(held) == len(names) else ("no: never" if not held else "no: only in " + ", ".join(held))
        rows.append({"id": fid, "finding": f["finding"], "cells": cells, "survives": survives})
    return rows


def robustness_table(readings: Mapping[str, Sequence[Mapping[str, Any]]]) -> tuple[list[str], list[list[str]]]:
    """``(header, rows)``: finding, then per reading "verdict: estimate [low, high]", then
    whether it survives every reading."""
    names = list(readings)
    rows = [[r["finding"]] + [f"**{r['cells'][n][0]}**: {r['cells'][n][1]}" for n in names] + [r["survives"]]
            for r in robustness_rows(readings)]
    return ["finding"] + names + ["reproduced in every reading"], rows
