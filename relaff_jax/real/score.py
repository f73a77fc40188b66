"""How well a segmentation matches the hand segmentation: IoU per object.

Takes two segment maps of one scene (``cloud.SEG_*`` convention, same shape); gives per hand
object its IoU with the predicted object matched to it (one-to-one, the matching that
maximises the summed IoU: ``scipy.optimize.linear_sum_assignment``; an unmatched object
scores 0), and the table's IoU. ``score_scene`` / ``score_scenes`` run ``segment.segment_scene``
on real files that carry labels and return these figures per scene and their mean.
"""
from __future__ import annotations

import os

import jax
import numpy as np
from scipy.optimize import linear_sum_assignment

from relaff_jax.errors import UserError

from .cloud import SEG_TABLE
from relaff_jax.config.real import RealConfig
from .readers import read_cloud
from .segment import hand_segmentation, object_ids, segment_scene
from relaff_jax.data.progress import progress_bar


def iou(a, b) -> float:
    """|a & b| / |a | b| of two boolean masks (0 when both are empty)."""
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 0.0


def object_ious(pred, truth) -> dict:
    """IoU per hand object (see the module docstring). pred, truth: segment maps of one shape.

    Returns dict(ious {true id: IoU}, match {true id: predicted id or None}, mean (float, over
    the hand objects; NaN if there are none), table (IoU of the two table masks))."""
    pred, truth = np.asarray(pred), np.asarray(truth)
    if pred.shape != truth.shape:
        raise UserError(f"segment maps differ in shape: {pred.shape} vs {truth.shape}")
    t_ids, p_ids = object_ids(truth), object_ids(pred)
    m = np.array([[iou(truth == t, pred == p) for p in p_ids] for t in t_ids]).reshape(len(t_ids), len(p_ids))
    ious = {t: 0.0 for t in t_ids}
    match = {t: None for t in t_ids}
    if m.size:
        rows, cols = linear_sum_assignment(-m)
        for r, c in zip(rows, cols):
            ious[t_ids[r]], match[t_ids[r]] = float(m[r, c]), p_ids[c]
    mean = float(np.mean(list(ious.values()))) if ious else float("nan")
    return dict(ious=ious, match=match, mean=mean, table=iou(pred == SEG_TABLE, truth == SEG_TABLE))


def score_scene(cloud, key, cfg: RealConfig = RealConfig(), known_count: bool = False) -> dict:
    """Segment one labelled ``RealCloud`` with the paper's pipeline and score it.

    ``known_count``: k = (hand objects + 1) instead of ``cfg.kmeans.k``. Returns the
    ``object_ious`` dict plus scene (file name), n_true (hand objects), k (clusters used) and
    seg (the pipeline's segment map)."""
    if cloud.label is None:
        raise UserError(f"{cloud.path or 'the cloud'} has no label field: nothing to score against")
    truth = hand_segmentation(cloud.label)
    n_true = len(object_ids(truth))
    if n_true == 0:  # a single plane (or a scene labelled table only): an IoU mean over no objects is NaN
        raise UserError(f"{cloud.path or 'the cloud'}: its hand segmentation holds no object (every point is table "
                        "or background, e.g. a single-plane cloud): nothing to score")
    res = segment_scene(cloud, key, cfg, n_objects=n_true if known_count else None)
    out = object_ious(res["seg"], truth)
    out.update(scene=os.path.basename(cloud.path), n_true=n_true, k=res["k"], seg=res["seg"])
    return out


def score_scenes(paths, seed: int = 0, cfg: RealConfig = RealConfig(), known_count: bool = False,
                 progress: bool = False) -> dict:
    """``score_scene`` on every file of ``paths`` (scene i gets ``fold_in(key(seed), i)``).

    Returns dict(scenes [per-scene dicts without seg], mean_iou (mean over scenes of the
    per-scene object mean), mean_iou_objects (mean over all hand objects), mean_table_iou)."""
    paths = list(paths)
    if not paths:
        raise UserError("no scenes to score")

    base = jax.random.key(seed)
    rows = []
    bar = progress_bar(progress, len(paths), "segment (first scene compiles)", unit="scene")
    for i, p in enumerate(paths):
        r = score_scene(read_cloud(p), jax.random.fold_in(base, i), cfg, known_count)
        r.pop("seg")
        rows.append(r)
        bar.set_description("segment")
        bar.update(1)
    bar.close()
    all_obj = [v for r in rows for v in r["ious"].values()]
    return dict(scenes=rows, mean_iou=float(np.mean([r["mean"] for r in rows])),
                mean_iou_objects=float(np.mean(all_obj)) if all_obj else float("nan"),
                mean_table_iou=float(np.mean([r["table"] for r in rows])))
