"""One 3D panel of two voxel clouds with their PCA frames, shared by the simulated
(``perception.plots``) and the real (``real.show``) scene pictures.

Takes numpy only: per object its points ``(n_o, 3)``, a label, a colour, its PCA frame
``(centroid (3,), frame (3, 3), eigenvalues (3,))`` or None when it is unseen. Draws into a
matplotlib 3D axes; no pyplot.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

FRAME_COLOURS = ("r", "g", "b")


def marker_size(n: int) -> float:
    """Scatter marker area for a cloud of n voxels: a small cloud (a toy of ~80 voxels beside an
    object of ~700) gets larger markers so that it stays visible."""
    return float(np.clip(600.0 / max(n, 1), 2.0, 14.0))


def draw_clouds(ax, points: Sequence[np.ndarray], labels: Sequence[str], colours: Sequence,
                frames: Sequence[tuple | None], title: str, min_half: float,
                axis_labels: tuple[str, str, str] = ("x (m)", "y (m)", "z (m)")) -> None:
    """Scatter each cloud, its PCA axes (2 sqrt(eigenvalue) long, at least 4 cm), equal aspect
    around the middle of all clouds' box, at least ``2 * min_half`` wide.

    points[o]: (n_o, 3) float; frames[o]: (centroid, frame (3, 3) columns = axes, eigenvalues)
    or None (unseen: no axes drawn).
    """
    # Draw order by zorder, not by mplot3d's depth sort, so the smaller cloud is drawn on top.
    ax.computed_zorder = False
    order = np.argsort([-len(p) for p in points], kind="stable")
    for rank, o in enumerate(order):
        p = np.asarray(points[o]).reshape(-1, 3)
        ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=marker_size(len(p)), c=[colours[o]], label=labels[o],
                   depthshade=False, zorder=2 + rank)
    for o, fr in enumerate(frames):
        if fr is None:
            continue
        mu, frame, ev = fr
        for k, c in enumerate(FRAME_COLOURS):
            vec = frame[:, k] * max(2 * np.sqrt(max(float(ev[k]), 0.0)), 0.04)
            ax.quiver(*mu, *vec, color=c, linewidth=2, zorder=10)
    # Middle of the clouds' box, not their mean: the larger object would push the smaller one
    # out of the axes.
    pts = np.concatenate([np.asarray(p).reshape(-1, 3) for p in points] + [np.zeros((0, 3))])
    lo, hi = (pts.min(0), pts.max(0)) if len(pts) else (np.zeros(3), np.zeros(3))
    centre, half = (lo + hi) / 2, max(min_half, 0.55 * float(np.max(hi - lo)))
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(0, 2 * half)
    # zoom < 1 leaves room for the axis labels, which tight_layout cannot see on a 3D axes
    ax.set_box_aspect((1, 1, 1), zoom=0.85)
    for setter, text in zip((ax.set_xlabel, ax.set_ylabel, ax.set_zlabel), axis_labels):
        setter(text, labelpad=2)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title, fontsize=9)
