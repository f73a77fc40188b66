"""The report's "Physics audit" section: each dataset's audited rollouts beside its labels.

Takes the datasets' stored audits (``DIR/audit.json``, ``relaff_jax.data.audit``: a MuJoCo C
replay of a sample of the rollouts with every step's contacts read) and the report folder;
gives ``stored_audits`` (the audits a set of dataset folders holds), ``audit_figure``
(``fig_audit.png``: per action the share of audited rollouts failing each check, and the press
(the force on an object held 0.1 s) in weights of the heavier object against its bound) and
``audit_blocks`` (the section: text, the table, the figure).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from matplotlib.figure import Figure

from relaff_jax import io as rio
from relaff_jax.data import audit as A
from relaff_jax.report import folder as F
from relaff_jax.report.figures import save_png
from relaff_jax.data.store import read_sidecar

CHECKS = (("palm_contact", "palm on an object from above"),
          ("force", f"press > {A.FORCE_WEIGHTS:g} weights and {A.FORCE_FLOOR_N:g} N"),
          ("penetration", f"penetration held 0.1 s > {1000 * A.PENETRATION_M:g} mm"),
          ("moving", f"moving > {A.MOVING_M_S:g} m/s at measuring"))


def stored_audits(data_dirs: Mapping[str, str | os.PathLike]) -> tuple[dict[str, Any], dict[str, str]]:
    """``({action: audit}, {action: why missing})`` from each folder's ``audit.json`` of the
    current schema made for its current selection with the dataset's programs (any sample size
    and seed)."""
    found, missing = {}, {}
    for act, d in data_dirs.items():
        try:
            a = rio.read_json(Path(d) / A.AUDIT_FILE)
            meta = read_sidecar(Path(d))
            sel = meta.get("selection", {}).get("sha256")
        except (OSError, ValueError) as e:
            missing[act] = f"no {A.AUDIT_FILE} ({type(e).__name__})"
            continue
        if not isinstance(a, dict) or a.get("version") != A.AUDIT_VERSION or a.get("selection_sha256") != sel:
            missing[act] = f"{A.AUDIT_FILE} of another version or selection"
            continue
        if a.get("programs", "v2") != A.recorded_programs(meta):  # as data.audit.stored_audit
            missing[act] = f"{A.AUDIT_FILE} replayed with other programs than the dataset's"
            continue
        found[act] = a
    return found, missing


def audit_figure(audits: Mapping[str, Mapping[str, Any]], out: Path) -> Path:
    """``fig_audit.png``: left, per action the share of audited rollouts failing each check;
    right, the press / weight of every audited rollout (log scale) and the bound."""
    acts = list(audits)
    fig = Figure(figsize=(12, 4.0))
    ax, bx = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.3, 1]})
    w = 0.8 / len(CHECKS)
    for k, (key, label) in enumerate(CHECKS):
        vals = [audits[a]["checks"][key]["share"] for a in acts]
        ax.bar(np.arange(len(acts)) + (k - 1.5) * w, [np.nan if v is None else v for v in vals], w, label=label)
    ax.set_xticks(np.arange(len(acts)), acts, rotation=30, fontsize=8)
    ax.set(ylim=(0, 1.3), ylabel="share of audited rollouts", title="Rollouts failing each physics check")
    ax.set_yticks(np.linspace(0, 1, 6))
    ax.legend(fontsize=7, loc="upper center", ncol=2)
    for i, a in enumerate(acts):
        y = [r["press_weights"] for r in audits[a]["rollouts"] if r["press_weights"]]
        bx.scatter(np.full(len(y), i) + np.linspace(-0.25, 0.25, len(y)) if y else [], y, s=8, alpha=0.6)
    bx.axhline(A.FORCE_WEIGHTS, color="r", lw=0.8, ls="--", label=f"bound {A.FORCE_WEIGHTS:g}")
    bx.axhline(1.0, color="k", lw=0.6, ls=":", label="resting on the table")
    bx.set_yscale("log")
    bx.set_xticks(np.arange(len(acts)), acts, rotation=30, fontsize=8)
    bx.set(ylabel="force held 0.1 s / weight", title="Press per audited rollout")
    bx.legend(fontsize=7)
    fig.tight_layout()
    return save_png(fig, out, dpi=100)


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _side(c: Mapping[str, Any]) -> str:
    """The share of rollouts with a palm contact from the side and its largest force."""
    top = c["side_force_n"]["max"]
    return _pct(c["side_share"]) + ("" if top is None else f" ({top:.1f})")


def audit_blocks(audits: Mapping[str, Mapping[str, Any]], missing: Mapping[str, str], out: Path) -> list[tuple]:
    """The "Physics audit" section: what is checked, one row per dataset, the figure."""
    blocks: list[tuple] = [("h", 2, "Physics audit"), (
        "p", "Per dataset, a sample of the selected samples whose program ran, replayed in MuJoCo C from the stored "
        "settled scene with the dataset's recorded config, every step's contacts read (`relaff audit DIR`, "
        "docs/audit.md). A rollout fails a check when the hand's palm touches an object from above with more than "
        f"{A.PALM_FORCE_N:g} N (the contact normal within {A.PALM_ABOVE_DEG:g} degrees of vertical: the palm pressing on "
        "an object's top; a lighter touch is not checked, and a contact from "
        "the side, the palm pushing an object aside, is reported in `palm side`, not checked); when the summed contact "
        f"normal force on an object held over 0.1 s (a press, not an impact) exceeds {A.FORCE_WEIGHTS:g} weights of "
        f"the heavier object and {A.FORCE_FLOOR_N:g} N (the least squeeze of two pads on a light pair); when a contact with an "
        f"object held over 0.1 s is deeper than {1000 * A.PENETRATION_M:g} mm (an impact's one-step depth is in "
        "audit.json, `peak_metres`); when an object not held by the hand moves faster than "
        f"{A.MOVING_M_S:g} m/s "
        "at the step whose positions the goal reads. Shares of failing rollouts, over all audited and over the "
        "positives; `label agr.`: the replay's labels equal to the stored ones.")]
    if audits:
        header = ["action", "engine", "audited", "palm above", "palm above (pos.)", "palm side (max N)", "press/weight med / p95 / max",
                  "held pen. max (mm)", "moving", "moving (pos.)", "label agr."]
        rows = []
        for act, a in audits.items():
            c, pos = a["checks"], a.get("by_label", {}).get("positive", {})
            wt = c["force"]["weights"]
            f = "-" if wt["median"] is None else f"{wt['median']:.0f} / {wt['p95']:.0f} / {wt['max']:.0f}"
            pen = c["penetration"]["metres"]["max"]
            share = lambda k: _pct(pos[k] / pos["n"]) if pos.get("n") else "-"
            rows.append([act, a["engine"], f"{a['n_audited']} of {a['population']}", _pct(c["palm_contact"]["share"]),
                         share("palm_contact"), _side(c["palm_contact"]), f, "-" if pen is None else f"{1000 * pen:.1f}",
                         _pct(c["moving"]["share"]), share("moving"), _pct(a["replay"]["label_agreement"])])
        blocks.append(("table", header, rows))
        audit_figure(audits, out / F.FIG_AUDIT)
        blocks.append(("img", F.FIG_AUDIT, "Physics audit: failing shares per check, and the press (the force on an "
                       "object held 0.1 s) of each audited rollout in weights of the heavier object"))
    if missing:
        blocks.append(("p", "No audit for " + "; ".join(f"{a} ({why})" for a, why in missing.items())
                       + "; `relaff audit DIR` makes them."))
    return blocks
