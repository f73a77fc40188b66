"""What a dataset's labels consist of: reach or relation (``relaff anatomy``).

Takes a finished dataset directory (or its arrays); gives ``anatomy(path)``, a
JSON-serialisable dict, and ``format_anatomy(d)``, the table ``relaff anatomy`` prints.

Why: an infeasible motor program (the arm cannot reach the object) is labelled negative, and
with the paper's centre-distance-matched negatives the negatives of a stacking action are
mostly stacked pairs out of reach. A label can then say "reachable" more than "how the two
objects stand". The anatomy counts both, over every rollout and over the balanced
selection, and scores three rules that see one cause each on the selection:

* ``oracle_feasible_acc``: label = feasible (a fixed rule, nothing fitted);
* ``oracle_relation_acc``: each relation predicts its majority label in the selection
  (3 cells; ties predict negative);
* ``oracle_feasible_relation_acc``: the same over the 6 (feasible, relation) cells.

The two fitted rules are scored on the data they were fitted on; with 3 or 6 cells over
N samples their optimism is at most a few cells' worth (an upper bound on what the variable
alone explains).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from relaff_jax.constants import RELATIONS
from relaff_jax.data.errors import DatasetError
from relaff_jax.data.layout import stored_scheme
from relaff_jax.data.load import load_rollouts
from relaff_jax.data.store import read_sidecar

QUANTILES = (0.1, 0.5, 0.9)


def _cells(label: np.ndarray, feasible: np.ndarray, relation: np.ndarray) -> dict[str, dict[str, Any]]:
    """``{"feasible|relation": {n, positives, label_rate}}`` over the 2 x 3 cells."""
    out = {}
    for f in (True, False):
        for r in RELATIONS:
            m = (feasible == f) & (relation == r)
            n, p = int(m.sum()), int(label[m].sum())
            out[f"{'feasible' if f else 'infeasible'}|{r}"] = {"n": n, "positives": p,
                                                              "label_rate": p / n if n else None}
    return out


def _majority_acc(label: np.ndarray, *groups: np.ndarray) -> float | None:
    """Accuracy of "each cell of ``groups`` predicts its majority label" (ties: negative)."""
    if not len(label):
        return None
    key = np.unique(np.stack([np.unique(g, return_inverse=True)[1] for g in groups], -1), axis=0,
                    return_inverse=True)[1].ravel()
    pos = np.bincount(key, weights=label.astype(float))
    n = np.bincount(key)
    predict = (pos / n > 0.5)[key]
    return float((predict == label).mean())


def _quantiles(x: np.ndarray) -> list[float] | None:
    return [float(q) for q in np.quantile(x, QUANTILES)] if len(x) else None


def _distances(dist: np.ndarray, label: np.ndarray, relation: np.ndarray) -> dict[str, Any]:
    """Centre-distance quantiles (``QUANTILES``) by class and by relation, and by both."""
    out: dict[str, Any] = {"positives": _quantiles(dist[label]), "negatives": _quantiles(dist[~label])}
    for r in RELATIONS:
        out[r] = _quantiles(dist[relation == r])
        out[f"positives|{r}"] = _quantiles(dist[label & (relation == r)])
        out[f"negatives|{r}"] = _quantiles(dist[~label & (relation == r)])
    return out


def anatomy_of(label: np.ndarray, feasible: np.ndarray, relation: np.ndarray, cog_distance: np.ndarray,
               selected: np.ndarray) -> dict[str, Any]:
    """The anatomy of R rollouts: ``label, feasible, selected (R,) bool``, ``relation (R,) str``,
    ``cog_distance (R,) float``. Keys: ``rollouts`` and ``selection``, each with ``n``,
    ``positives``, ``feasible``, ``cells`` (``_cells``), ``distance_quantiles``; the selection
    also ``negatives_infeasible_share`` and the three oracles (module docstring)."""
    label, feasible, selected = (np.asarray(a, bool) for a in (label, feasible, selected))
    relation, dist = np.asarray(relation).astype(str), np.asarray(cog_distance, float)
    out: dict[str, Any] = {}
    for name, m in (("rollouts", np.ones(label.shape, bool)), ("selection", selected)):
        lab, fea, rel, d = label[m], feasible[m], relation[m], dist[m]
        part = {"n": int(m.sum()), "positives": int(lab.sum()), "feasible": int(fea.sum()),
                "label_rate": float(lab.mean()) if len(lab) else None,
                "feasible_rate": float(fea.mean()) if len(lab) else None,
                "cells": _cells(lab, fea, rel), "distance_quantiles": _distances(d, lab, rel)}
        neg = ~lab
        part["negatives_infeasible_share"] = float((neg & ~fea).sum() / neg.sum()) if neg.any() else None
        part["positives_infeasible"] = int((lab & ~fea).sum())
        part["oracle_feasible_acc"] = float((fea == lab).mean()) if len(lab) else None
        part["oracle_relation_acc"] = _majority_acc(lab, rel)
        part["oracle_feasible_relation_acc"] = _majority_acc(lab, fea, rel)
        out[name] = part
    return out


def anatomy(path: str | os.PathLike) -> dict[str, Any]:
    """``anatomy_of`` a finished dataset, with its action, population, negatives and borrowing."""
    path = Path(path)
    meta = read_sidecar(path)
    if meta["status"] != "complete":
        raise DatasetError(f"{path}: the dataset is still generating; its anatomy needs the selection")
    r = load_rollouts(path)
    if "feasible" not in r:
        raise DatasetError(f"{path}: the rollouts have no 'feasible' field, so reach and relation cannot be told apart")
    out = anatomy_of(r["label"], r["feasible"], r["relation"], r["cog_distance"], r["selected"])
    sel = meta.get("selection", {})
    scheme = stored_scheme(meta.get("selection_scheme", {}))
    out.update(action=meta["action"], path=str(path), population=scheme["population"],
               negatives=scheme["negatives"], unsettled=scheme["unsettled"],
               unsettled_refused=sel.get("unsettled_refused"), borrowed=sel.get("borrowed"),
               borrowed_share=(sel["borrowed"] / sel["n_negative"]) if sel.get("n_negative") else None,
               matching_met=sel.get("matching_met", True), quantiles=list(QUANTILES))
    return out


def _f(x: float | None, spec: str = ".3f") -> str:
    return "-" if x is None else format(x, spec)


def format_anatomy(d: Mapping[str, Any]) -> str:
    """Human-readable table of an ``anatomy`` dict."""
    s, r = d["selection"], d["rollouts"]
    refused = "" if d["unsettled_refused"] is None else f" ({d['unsettled_refused']} refused)"
    lines = [f"dataset {d['path']}: action {d['action']}, population {d['population']}, negatives {d['negatives']}, "
             f"unsettled {d['unsettled']}{refused}",
             f"rollouts {r['n']} ({r['feasible']} feasible, {r['positives']} positive); "
             f"selection {s['n']} ({s['feasible']} feasible, {s['positives']} positive)",
             f"negatives infeasible in the selection: {_f(s['negatives_infeasible_share'], '.1%')} "
             f"(all rollouts: {_f(r['negatives_infeasible_share'], '.1%')})",
             f"borrowed negatives: {d['borrowed']} ({_f(d['borrowed_share'], '.1%')})"
             + ("" if d["matching_met"] else "  ** distance matching NOT met **"),
             "",
             "oracles on the selection: label = feasible {}, relation {}, feasible + relation {}".format(
                 _f(s["oracle_feasible_acc"]), _f(s["oracle_relation_acc"]), _f(s["oracle_feasible_relation_acc"])),
             "",
             f"{'cell':<20} {'sel n':>6} {'pos':>5} {'rate':>6} {'all n':>7} {'pos':>6} {'rate':>6}"]
    for key, c in s["cells"].items():
        a = r["cells"][key]
        lines.append(f"{key:<20} {c['n']:>6} {c['positives']:>5} {_f(c['label_rate'], '.2f'):>6} "
                     f"{a['n']:>7} {a['positives']:>6} {_f(a['label_rate'], '.2f'):>6}")
    q = "/".join(f"{int(100 * x)}" for x in d["quantiles"])
    lines += ["", f"centre distance, m ({q} %), selection"]
    for key, v in s["distance_quantiles"].items():
        if "|" not in key:
            lines.append(f"  {key:<12} " + ("-" if v is None else " ".join(f"{x:.2f}" for x in v)))
    return "\n".join(lines)
