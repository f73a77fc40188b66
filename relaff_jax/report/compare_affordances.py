"""``relaff compare``'s per-affordance table: each run's answer to "does what the robot knows
help this affordance?" side by side.

Takes each report's ``summary.json`` (its ``affordances`` entry per space, written by
``report.affordances.summary`` beside ``affordances.csv``); gives ``check`` (one ``UserError``
naming a report without the answers, before any page is made), ``table`` (per space: each
affordance a row, each run's verdict with the gain, bf and samples saved and their intervals,
and whether the verdict is the same in every run), ``lines`` (the markdown section) and
``verdict_lines`` (the short table the terminal prints beside a written page). Nothing is
recomputed: the cells are the reports' numbers.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

from relaff_jax.constants import ACTIONS
from relaff_jax.errors import UserError
from relaff_jax.learn.user_rows import NOT_IN_PAPER
from relaff_jax.report import folder as F
from relaff_jax.report.formatting import fmt, interval


def _answers(summary: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    """``{space: summary[space]["affordances"]}`` for the spaces that have rows."""
    out = {}
    for space in ("pca", "rhf"):
        x = summary.get(space)
        if isinstance(x, Mapping) and isinstance(x.get("affordances"), Mapping) and x["affordances"].get("rows"):
            out[space] = x["affordances"]
    return out


def check(summaries: Mapping[str, Mapping[str, Any]], paths: Mapping[str, str | os.PathLike]) -> None:
    """A ``UserError`` naming the first report without per-affordance answers (no
    ``affordances.csv``, or a ``summary.json`` without its ``affordances`` rows)."""
    for name, s in summaries.items():
        p = Path(paths[name])
        if not (p / F.AFFORDANCES_CSV).exists() or not _answers(s):
            missing = F.AFFORDANCES_CSV if not (p / F.AFFORDANCES_CSV).exists() else f"{F.SUMMARY}'s affordances"
            raise UserError(f"{p} has no per-affordance answers ({missing} is missing: a report written before "
                            "they existed); write it again with relaff report")


def _ci(x: Any, nd: int) -> str:
    lo, hi = (list(x) + [None, None])[:2] if x else (None, None)
    text = interval(_num(lo), _num(hi), nd)
    return "" if text == "-" else " " + text


def _num(x: Any) -> float:
    return float("nan") if x is None else float(x)


def cell(row: Mapping[str, Any] | None) -> str:
    """One run's answer for one affordance: verdict, gain, bf of the best row and samples
    saved, each with its interval ("-" where the run has no such affordance)."""
    if row is None:
        return "-"
    saved = fmt(_num(row.get("samples_saved")), 1) + _ci(row.get("samples_saved_ci"), 1)
    if row.get("samples_saved_censored"):
        saved += " (censored)"
    gain = _num(row.get("gain"))
    g = "-" if gain != gain else f"{gain:+.3f}"
    gi = row.get("gain_ci") or [None, None]
    g_ci = "" if gi[0] is None and gi[1] is None else f" [{_signed(gi[0])}, {_signed(gi[1])}]"
    return (f"**{row.get('verdict', '-')}**: gain {g}{g_ci}; bf {fmt(_num(row.get('bf_best')), 2)}"
            f"{_ci(row.get('bf_best_ci'), 2)}; saved {saved}")


def _signed(x: Any) -> str:
    return "-" if x is None or x != x else f"{float(x):+.3f}"


def _order(targets: set) -> list[str]:
    return [a for a in ACTIONS if a in targets] + sorted(targets - set(ACTIONS))


def same_verdict(verdicts: Mapping[str, str | None]) -> str:
    """"yes: V" where every run gives verdict V; else "no: " and which runs say what (a run
    without the affordance: "not in RUN")."""
    said: dict[str | None, list[str]] = {}
    for run, v in verdicts.items():
        said.setdefault(v, []).append(run)
    if len(said) == 1 and None not in said:
        return f"yes: {next(iter(said))}"
    return "no: " + "; ".join(f"{v or 'not'} in {', '.join(runs)}" for v, runs in said.items())


def table(summaries: Mapping[str, Mapping[str, Any]], space: str) -> tuple[list[str], list[list[str]]]:
    """``(header, rows)`` of one space: affordance, each run's ``cell``, whether the verdict is
    the same in every run (the paper's affordances first; a user action labelled)."""
    names = list(summaries)
    ans = {n: _answers(summaries[n]).get(space, {}).get("rows", {}) for n in names}
    rows = []
    for t in _order({t for n in names for t in ans[n]}):
        in_paper = t in ACTIONS
        rows.append([t if in_paper else f"{t} ({NOT_IN_PAPER})"] + [cell(ans[n].get(t)) for n in names]
                    + [same_verdict({n: (ans[n][t]["verdict"] if t in ans[n] else None) for n in names})])
    return ["affordance"] + names + ["same verdict in every run"], rows


def spaces(summaries: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """The spaces with per-affordance answers in at least one run, PCA first."""
    return [s for s in ("pca", "rhf") if any(s in _answers(x) for x in summaries.values())]


def lines(summaries: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """The markdown section: per space what each cell rests on, then the table."""
    out = ["## Per affordance: does what the robot knows help it, in every run", ""]
    for space in spaces(summaries):
        rests = []
        for n, s in summaries.items():
            a = _answers(s).get(space)
            if a:
                level = a.get("ci_level")
                rests.append(f"`{n}`: bf and gain of '{a.get('best_row')}', samples saved of "
                             f"'{a.get('samples_saved_method')}'"
                             + (f", {100 * float(level):g} % intervals" if level is not None else ", no intervals"))
        header, rows = table(summaries, space)
        out += [f"{space.upper()}: each run's verdict (from the gain's interval: 'helps' above 0, 'hurts' below, "
                "'no evidence' across it), then the gain over NB in the window, the bootstrap factor and the samples "
                "saved at n = 10, each [interval]. " + "; ".join(rests) + ".", "",
                "| " + " | ".join(header) + " |", "|---|" + "---|" * (len(header) - 1)]
        out += ["| " + " | ".join(r) + " |" for r in rows] + [""]
    return out


def verdict_lines(summaries: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Plain text for the terminal: per space each affordance's verdict in every run and
    whether it is the same."""
    out = []
    for space in spaces(summaries):
        header, rows = table(summaries, space)
        names = header[1:-1]
        ans = {n: _answers(summaries[n]).get(space, {}).get("rows", {}) for n in names}
        out.append(f"per affordance ({space.upper()}): " + " | ".join(names) + " | same verdict in every run")
        for r in rows:
            t = r[0].split(" (")[0]
            out.append(f"  {r[0]}: " + " | ".join(ans[n][t]["verdict"] if t in ans[n] else "-" for n in names)
                       + f" | {r[-1]}")
    return out
