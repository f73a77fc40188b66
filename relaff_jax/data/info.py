"""Counts and positive rates of a dataset, as a dict and as a text table.

Takes a dataset directory (finished or still generating); gives ``info(path)``, a
JSON-serialisable dict (samples, rollouts, positive rates by relation and by object pair,
borrowed negatives, attached features, config, versions), and ``format_info(d)``, the table
that ``relaff info`` prints.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from relaff_jax.constants import RELATIONS
from relaff_jax.data.load import load_dataset, load_rollouts, read_features_sidecar
from relaff_jax.data.layout import stored_scheme
from relaff_jax.data.store import read_sidecar


def _rates(label: np.ndarray, groups: np.ndarray, keys: Sequence[str]) -> tuple[dict, dict]:
    rate, count = {}, {}
    for key in keys:
        m = groups == key
        k, p = int(m.sum()), int(label[m].sum())
        rate[key] = p / k if k else None
        count[key] = {"n": k, "positives": p}
    return rate, count


def _group_stats(prefix: str, d: Mapping[str, np.ndarray]) -> dict[str, Any]:
    label = d["label"]
    n = len(label)
    pair = np.char.add(np.char.add(d["toy"].astype(str), "/"), d["other"].astype(str)) if n else np.zeros(0, str)
    rel_rate, rel_count = _rates(label, d["relation"], RELATIONS)
    pair_rate, pair_count = _rates(label, pair, sorted(set(pair.tolist())))
    return {
        f"{prefix}positive_rate": float(label.mean()) if n else None,
        f"{prefix}positive_rate_by_relation": rel_rate,
        f"{prefix}count_by_relation": rel_count,
        f"{prefix}positive_rate_by_pair": pair_rate,
        f"{prefix}count_by_pair": pair_count,
    }


def info(path: str | os.PathLike) -> dict[str, Any]:
    """Counts and positive rates of a dataset (JSON-serialisable).

    Keys: ``action``, ``status``, ``n`` (selected samples), ``n_positive``, ``n_negative``,
    ``positive_rate``, ``positive_rate_by_relation`` {relation: rate or None},
    ``count_by_relation`` {relation: {n, positives}}, ``positive_rate_by_pair`` and
    ``count_by_pair`` keyed ``"toy/other"`` -- all over the selected samples; the same with a
    ``rollouts_`` prefix over every rollout; ``rollouts``, ``chunks``, ``batch``, ``seed``,
    ``borrowed`` (negatives taken outside their distance bin), ``borrowed_share``,
    ``matching_met`` (False: the matching was given up at the cap or ``match_patience``),
    ``population``, ``negatives`` and ``unsettled`` (the selection's settings),
    ``unsettled_refused`` (executed rollouts never at rest, refused; None: not recorded or not
    known), ``config``, ``versions``; and
    ``features``: None, or {status, chunks, arrays {name: {shape, dtype}}, unseen_samples
    (samples with any unseen flag set), unseen_by_column}.
    """
    path = Path(path)
    meta = read_sidecar(path)
    rollouts = load_rollouts(path)
    out: dict[str, Any] = {
        "path": str(path),
        "action": meta["action"],
        "status": meta["status"],
        "seed": meta["seed"],
        "batch": meta["batch"],
        "requested_n": meta["n_samples"],
        "rollouts": len(rollouts["label"]),
        "chunks": meta["counts"]["chunks"],
    }
    sel = rollouts["selected"]
    chosen = {k: v[sel] for k, v in rollouts.items() if isinstance(v, np.ndarray)}
    out["n"] = int(sel.sum())
    out["n_positive"] = int(chosen["label"].sum())
    out["n_negative"] = out["n"] - out["n_positive"]
    out.update(_group_stats("", chosen))
    out.update(_group_stats("rollouts_", rollouts))
    sel_meta = meta.get("selection", {})
    out["borrowed"] = sel_meta.get("borrowed")
    out["borrowed_share"] = sel_meta.get("borrowed_share")
    out["matching_met"] = sel_meta.get("matching_met", True if sel_meta else None)
    scheme = stored_scheme(meta.get("selection_scheme", {}))
    for k in ("population", "negatives", "unsettled"):
        out[k] = scheme[k]
    out["unsettled_refused"] = sel_meta.get("unsettled_refused")
    out["features"] = None
    fmeta = read_features_sidecar(path)
    if fmeta is not None:
        feat: dict[str, Any] = {"status": fmeta["status"], "chunks": fmeta["chunks"]}
        if fmeta["status"] == "complete" and meta["status"] == "complete":
            data = load_dataset(path)
            names = [k for k in data if k not in chosen and k != "action"]
            feat["arrays"] = {k: {"shape": list(data[k].shape), "dtype": data[k].dtype.name} for k in names}
            if "unseen" in data:
                u = data["unseen"].reshape(len(data["unseen"]), -1)
                feat["unseen_samples"] = int(u.any(axis=1).sum())
                feat["unseen_by_column"] = u.sum(axis=0).astype(int).tolist()
        out["features"] = feat
    out["config"] = meta.get("config")
    out["versions"] = meta.get("versions")
    return out


def _fmt_rate(rate: float | None) -> str:
    return "-" if rate is None else f"{rate:6.1%}"


def format_info(d: Mapping[str, Any]) -> str:
    """Human-readable table of an ``info`` dict."""
    lines = [f"dataset {d['path']}: action {d['action']}, {d['status']}"]
    if d["status"] == "complete":
        lines.append(
            f"samples: {d['n']} ({d['n_positive']} positive, {_fmt_rate(d['positive_rate']).strip()}) "
            f"from {d['rollouts']} rollouts in {d['chunks']} chunks; "
            f"{d['borrowed']} negatives borrowed across distance bins"
        )
        refused = "" if d["unsettled_refused"] is None else f" ({d['unsettled_refused']} refused)"
        lines.append(f"population {d['population']}, negatives {d['negatives']}, unsettled {d['unsettled']}{refused}"
                     + ("" if d["matching_met"] is not False else
                        f"; ** distance matching NOT met: {d['borrowed_share']:.1%} of the negatives borrowed **"))
    else:
        lines.append(f"generating: {d['rollouts']} rollouts in {d['chunks']} chunks, target {d['requested_n']} samples")
    lines.append(f"rollouts positive rate: {_fmt_rate(d['rollouts_positive_rate']).strip()}")
    lines.append("")
    lines.append(f"{'relation':<10} {'samples':>8} {'pos rate':>8} {'rollouts':>9} {'pos rate':>8}")
    for r in RELATIONS:
        c, rc = d["count_by_relation"][r], d["rollouts_count_by_relation"][r]
        lines.append(
            f"{r:<10} {c['n']:>8} {_fmt_rate(d['positive_rate_by_relation'][r]):>8} "
            f"{rc['n']:>9} {_fmt_rate(d['rollouts_positive_rate_by_relation'][r]):>8}"
        )
    lines.append("")
    pairs = sorted(d["rollouts_count_by_pair"])
    width = max([len("pair")] + [len(p) for p in pairs])
    lines.append(f"{'pair':<{width}} {'samples':>8} {'pos rate':>8} {'rollouts':>9} {'pos rate':>8}")
    for p in pairs:
        c = d["count_by_pair"].get(p, {"n": 0})
        lines.append(
            f"{p:<{width}} {c['n']:>8} {_fmt_rate(d['positive_rate_by_pair'].get(p)):>8} "
            f"{d['rollouts_count_by_pair'][p]['n']:>9} {_fmt_rate(d['rollouts_positive_rate_by_pair'][p]):>8}"
        )
    f = d.get("features")
    lines.append("")
    if f is None:
        lines.append("features: none")
    else:
        lines.append(f"features: {f['status']} ({f['chunks']} chunks)")
        for k, s in f.get("arrays", {}).items():
            lines.append(f"  {k:<10} {tuple(s['shape'])} {s['dtype']}")
        if "unseen_samples" in f:
            lines.append(f"  unseen flag set on {f['unseen_samples']} samples (by column {f['unseen_by_column']})")
    return "\n".join(lines)
