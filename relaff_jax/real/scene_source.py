"""A real scene with its hand segmentation, in the simulation-aligned table frame: what the
relation stages (labels, proposals, pictures, features, experiments) read.

Takes a scene file (``.pcd``, ``.ply``, ``.npz``: ``readers.read_cloud``) with a per-point
``label`` (0 invalid, 1-9 table, object id = label // 10 >= 2); gives ``load(path) ->
RealScene``: the cloud, the table plane (4,) fitted by least squares to the hand-labelled
table points, the camera ``height`` (m) and ``tilt_deg`` (``frame.camera_pose``), the frame
and ``objects``: ``{id: (N_i, 3) metres}`` in the *simulation-aligned table frame*:
``frame.table_frame(plane, flip=True)`` (z up, x towards the camera) shifted by ``TARGET``, so
that the camera stands where ``frame.sim_camera(height, tilt_deg, TARGET)`` puts the simulated
one and PCA positions of real and simulated objects are comparable.
"""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from relaff_jax.errors import UserError

from . import frame as rframe
from .readers import FORMATS, read_cloud
from .segment import hand_segmentation, SEG_TABLE
from .segment import object_ids as seg_object_ids

# Where the camera's optical axis meets the table, in the simulation's robot frame. With the
# real pose (0.59 m high, ~50 deg from straight down) the camera then stands over x ~ 1.1 m,
# the far edge of the simulated workspace (``SimRelationConfig.workspace_radius``), so that
# simulated objects lie 0.3-0.9 m in front of its foot, as the real objects do (0.2-0.75 m).
TARGET = (0.4, 0.0, 0.0)
MIN_TABLE_POINTS = 100


@dataclasses.dataclass(frozen=True, eq=False)
class RealScene:
    """One real scene in the simulation-aligned table frame (see the module docstring).

    xyz (H, W, 3) camera frame, rgb (H, W, 3) uint8, seg (H, W) hand segment map (object ids
    >= 2), plane (4,), frame (dict rotation, origin), height (m), tilt_deg, objects
    {id: (N_i, 3)} and normals-free point sets; ``to_sim(points_cam)`` maps camera points.
    """

    name: str
    xyz: np.ndarray
    rgb: np.ndarray
    seg: np.ndarray
    plane: np.ndarray
    frame: dict
    height: float
    tilt_deg: float
    objects: dict

    def to_sim(self, points: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) -> simulation-aligned table frame."""
        return rframe.to_table(points, self.frame) + np.asarray(TARGET)


def table_plane(xyz: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Least-squares plane (4,) (unit normal towards the camera) of the hand-labelled table."""
    pts = xyz[(seg == SEG_TABLE) & np.all(np.isfinite(xyz), axis=-1)].astype(np.float64)
    if len(pts) < MIN_TABLE_POINTS:
        raise UserError(f"{len(pts)} hand-labelled table points (labels 1-9); a table plane needs "
                        f">= {MIN_TABLE_POINTS}")
    c = pts.mean(0)
    n = np.linalg.svd(pts - c, full_matrices=False)[2][2]
    plane = np.r_[n, -n @ c]
    return -plane if plane[3] < 0 else plane


def object_ids(path: str | Path) -> list[int]:
    """Object ids (label // 10 >= 2) present in a scene file."""
    cloud = read_cloud(path)
    if cloud.label is None:
        raise UserError(f"{path}: no per-point label field, so no hand segmentation to label pairs on")
    return seg_object_ids(hand_segmentation(cloud.label))


def load(path: str | Path) -> RealScene:
    """Read ``path`` and express its hand-segmented objects in the simulation-aligned frame."""
    cloud = read_cloud(path)
    if cloud.label is None:
        raise UserError(f"{path}: no per-point label field (the hand segmentation is needed)")
    if not cloud.organized:
        raise UserError(f"{path}: an organized (image-shaped) cloud is needed for pictures and labels")
    seg = hand_segmentation(cloud.label)
    xyz = np.asarray(cloud.xyz, np.float64)
    plane = table_plane(xyz, seg)
    pose = rframe.camera_pose(plane)
    fr = rframe.table_frame(plane, flip=True)
    ok = np.all(np.isfinite(xyz), axis=-1)
    pts = rframe.to_table(xyz[ok], fr) + np.asarray(TARGET)
    ids = seg[ok]
    objects = {i: pts[ids == i] for i in seg_object_ids(seg)}
    if len(objects) < 2:
        raise UserError(f"{path}: {len(objects)} labelled object(s); a relation needs a pair")
    rgb = cloud.rgb if cloud.rgb is not None else np.zeros(xyz.shape, np.uint8)
    return RealScene(Path(path).name, xyz, rgb, seg, plane, fr, float(pose["height"]),
                     float(pose["tilt_deg"]), objects)


def scene_files(folder: str | Path) -> list[Path]:
    """Scene files of a folder (``.pcd``, ``.ply``, ``.npz``) in natural order (learn2 < learn10)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"scenes folder {folder} does not exist")
    files = [p for p in folder.iterdir() if p.suffix.lower() in FORMATS]
    if not files:
        raise UserError(f"{folder} holds no scene files ({', '.join(FORMATS)})")

    def key(p):
        return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]

    return sorted(files, key=key)
