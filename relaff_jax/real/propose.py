"""The geometric rule that proposes a relation for every object pair of a real scene.

Takes the hand-segmented objects of one scene in the table frame (``{id: (N_i, 3) metres}``,
z up, table at z = 0; ``scene_source.load``) and gives one ``Proposal`` per pair: ``beside``,
``on_top`` (upper object first) or ``none`` (left out of the labels), with the numbers the
rule used. The proposal is checked by eye on a picture (``pictures.py``) before it becomes a
label.

The rule (``RuleConfig`` holds the tolerances):

- an object's *bottom* and *top* are the ``lo_q`` and ``hi_q`` quantiles of its points' z
  (robust to sensor noise and stray labelled pixels);
- only an object whose bottom is above ``table_tol`` can be on another;
- A is *on top of* B when A does not rest on the table, A's bottom is within ``contact_tol``
  of B's top, and at least ``min_overlap`` of A's points lie (in x, y) inside B's footprint
  (the convex hull of B's points grown by ``grow``; the hull, because the part of B's top
  under A is hidden from the camera);
- an object *rests on the table* unless another object of the scene is under it (so an
  object whose bottom is hidden behind another still rests on the table);
- the pair is ``beside`` when both rest on the table;
- otherwise ``none`` (e.g. two boxes both on a third, or one on a third and one on the table).
"""
from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping

import numpy as np

from relaff_jax.config.real import RuleConfig
from relaff_jax.errors import UserError


@dataclasses.dataclass(frozen=True)
class Proposal:
    """The rule's answer for one pair: ids (upper first for on_top), relation and evidence."""

    object_a: int
    object_b: int
    relation: str  # "beside", "on_top" or "none"
    bottoms: tuple[float, float]
    tops: tuple[float, float]
    overlap: tuple[float, float]  # fraction of a's points over b's footprint, and of b's over a's


def _hull_contains(hull_pts: np.ndarray, pts: np.ndarray, grow: float) -> np.ndarray:
    """Which ``pts (M, 2)`` lie inside the convex hull of ``hull_pts (N, 2)`` grown by ``grow``."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(hull_pts)
    except QhullError:  # degenerate (a line or a point): use the distance to the points' centre
        return np.linalg.norm(pts - hull_pts.mean(0), axis=1) <= grow
    # equations: n . x + d <= 0 inside, n unit length
    eq = hull.equations
    return np.all(pts @ eq[:, :2].T + eq[:, 2] <= grow, axis=1)


def overlap_fraction(a: np.ndarray, b: np.ndarray, grow: float) -> float:
    """Fraction of ``a``'s points (N, 3) whose (x, y) fall inside ``b``'s grown footprint."""
    if len(a) == 0 or len(b) < 3:
        return 0.0
    return float(np.mean(_hull_contains(b[:, :2], a[:, :2], grow)))


def _extent(p: np.ndarray, cfg: RuleConfig) -> tuple[float, float]:
    lo, hi = np.quantile(p[:, 2], [cfg.lo_q, cfg.hi_q])
    return float(lo), float(hi)


def supports(bot_u: float, ov_u: float, top_l: float, cfg: RuleConfig) -> bool:
    """Does the lower object (top ``top_l``) carry the upper one (bottom ``bot_u``, a fraction
    ``ov_u`` of its points over the lower one's footprint)?"""
    return bot_u >= cfg.table_tol and abs(bot_u - top_l) <= cfg.contact_tol and ov_u >= cfg.min_overlap


def propose_scene(objects: Mapping[int, np.ndarray], cfg: RuleConfig = RuleConfig()) -> list[Proposal]:
    """One proposal per unordered pair of ``objects`` (ids ascending; on_top pairs upper first).

    An object rests on the table unless another object of the scene supports it (``supports``);
    that way an object whose bottom the camera cannot see (hidden behind another) still rests
    on the table when nothing under it could carry it.
    """
    if len(objects) < 2:
        raise UserError(f"a scene needs at least two objects to propose relations, got {len(objects)}")
    ids = sorted(objects)
    pts = {}
    for i in ids:
        p = np.asarray(objects[i], dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 3:
            raise UserError(f"object {i} needs (N >= 3, 3) points, got shape {p.shape}")
        pts[i] = p
    ext = {i: _extent(pts[i], cfg) for i in ids}
    ov = {(i, j): overlap_fraction(pts[i], pts[j], cfg.grow) for i in ids for j in ids if i != j}
    on = {(i, j): supports(ext[i][0], ov[i, j], ext[j][1], cfg) for (i, j) in ov}
    for i, j in itertools.combinations(ids, 2):  # both fit: the higher bottom is the upper one
        if on[i, j] and on[j, i]:
            on[i, j], on[j, i] = ext[i][0] >= ext[j][0], ext[j][0] > ext[i][0]
    on_table = {i: not any(on[i, j] for j in ids if j != i) for i in ids}
    out = []
    for i, j in itertools.combinations(ids, 2):
        if on[j, i]:
            i, j = j, i
        rel = "on_top" if on[i, j] else "beside" if on_table[i] and on_table[j] else "none"
        out.append(Proposal(i, j, rel, (ext[i][0], ext[j][0]), (ext[i][1], ext[j][1]), (ov[i, j], ov[j, i])))
    return out
