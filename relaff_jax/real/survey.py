"""Figures over a folder of real scenes: the camera's pose over the table, segmentation IoU.

Takes scene files (any ``readers.FORMATS``), a seed and a ``RealConfig``; gives
``camera_poses(paths, seed, cfg)`` -> dict(scenes [{scene, height, tilt_deg, plane (4,)}],
stats (``frame.camera_pose_stats``)) from each scene's RANSAC table plane (scene i gets
``fold_in(key(seed), i)``), and ``read_speed(paths)`` -> seconds per file of ``read_cloud``.
(IoU over scenes: ``score.score_scenes``.)
"""
from __future__ import annotations

import os
import time

import jax
import numpy as np

from relaff_jax.errors import UserError

from relaff_jax.config.real import RealConfig
from .frame import camera_pose, camera_pose_stats
from .readers import read_cloud
from .segment import fit_table_plane


def camera_poses(paths, seed: int = 0, cfg: RealConfig = RealConfig()) -> dict:
    """Camera height and tilt over each scene's table plane, and their mean and spread."""
    paths = list(paths)
    if not paths:
        raise UserError("no scenes given")
    base = jax.random.key(seed)
    rows = []
    for i, p in enumerate(paths):
        c = read_cloud(p)
        k_plane, _ = jax.random.split(jax.random.fold_in(base, i))  # the key segment_scene uses
        plane = fit_table_plane(c.xyz[c.valid].astype(np.float64), k_plane, cfg)["plane"]
        pose = camera_pose(plane)
        rows.append(dict(scene=os.path.basename(str(p)), height=pose["height"], tilt_deg=pose["tilt_deg"],
                         plane=plane))
    return dict(scenes=rows, stats=camera_pose_stats([r["plane"] for r in rows]))


def read_speed(paths, repeat: int = 1) -> dict:
    """Wall time of ``read_cloud`` per file: dict(n, mean_s, max_s, total_s) (best of ``repeat``)."""
    times = []
    for p in paths:
        best = np.inf
        for _ in range(repeat):
            t = time.perf_counter()
            read_cloud(p)
            best = min(best, time.perf_counter() - t)
        times.append(best)
    if not times:
        raise UserError("no files given")
    return dict(n=len(times), mean_s=float(np.mean(times)), max_s=float(np.max(times)), total_s=float(np.sum(times)))
