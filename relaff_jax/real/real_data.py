"""Real relation data: the labelled pairs of a scenes folder as features, and the real sensor.

Takes a scenes folder and its labels CSV (``labels.py``; checked against the files:
checksums, object ids); gives ``real_features(folder, labels, cfg) -> dict`` (``labels`` a file or its rows): ``pca
(N, 18)`` and ``rhf (N, 300)`` of each labelled pair (object a first: the upper object of an
``on_top`` pair; normals from the cloud, ``cloud_features``), ``y (N,)`` 1 = on_top, 0 =
beside, ``scene (N,)`` file names, ``a``, ``b`` (N,) ids; and per scene ``height``, ``tilt_deg``
(hand-labelled table plane, ``frame.camera_pose``) and ``vfov_deg`` (from the cloud's
intrinsics, given or estimated). Points are in the simulation-aligned table frame of
``scene_source`` so that real and simulated PCA states share one frame.
``scene_poses(folder, labels)`` gives the poses alone (no features: the sensor is known, and
a simulated folder checked, within seconds). ``sensor(data) -> SimSensor`` is the mean pose
and field of view. ``cached_real_features``
stores the result as an ``.npz`` keyed by the labels file's sha256 and the config.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import to_dict
from relaff_jax.data.progress import progress_bar
from relaff_jax.errors import UserError

from . import labels as lab
from .cloud_features import object_pair_features
from relaff_jax.config.real import RealConfig, SimSensor
from .frame import camera_pose, table_frame
from .readers import read_cloud
from .scene_source import TARGET, object_ids, table_plane
from .segment import hand_segmentation


def sim_aligned_frame(plane) -> dict:
    """``frame.table_frame(plane, flip=True)`` with its origin moved so that table coordinates
    come out shifted by ``scene_source.TARGET`` (the simulation's camera target)."""
    fr = table_frame(plane, flip=True)
    return dict(rotation=fr["rotation"], origin=fr["origin"] - fr["rotation"].T @ np.asarray(TARGET))


def _rows(labels) -> list:
    """A labels file's rows (path) or the rows themselves (list of ``labels.Label``)."""
    return lab.read_labels(labels) if isinstance(labels, (str, Path)) else list(labels)


def _pose(cloud) -> tuple[dict, np.ndarray, float]:
    """Camera pose (height, tilt_deg) over the hand-labelled table, the plane (4,), the vertical fov."""
    seg = hand_segmentation(cloud.label)
    plane = table_plane(np.asarray(cloud.xyz, np.float64), seg)
    fy = cloud.intrinsics[1] if cloud.intrinsics is not None else np.nan
    vfov = 2 * np.degrees(np.arctan(cloud.xyz.shape[0] / 2 / fy)) if cloud.organized else np.nan
    return camera_pose(plane), plane, vfov


def scene_poses(folder: str | Path, labels, progress: bool = False) -> dict:
    """``pose_scene``, ``height``, ``tilt_deg``, ``vfov_deg`` (S,) of the labelled scenes of
    ``folder``: what ``sensor`` needs, without the features (a second per scene)."""
    names = list(dict.fromkeys(r.scene for r in _rows(labels)))
    poses = {k: [] for k in ("pose_scene", "height", "tilt_deg", "vfov_deg")}
    bar = progress_bar(progress, len(names), f"camera poses ({Path(folder).name})", unit="scene")
    for name in names:
        pose, _, vfov = _pose(read_cloud(Path(folder) / name))
        for k, v in zip(poses, (name, pose["height"], pose["tilt_deg"], vfov)):
            poses[k].append(v)
        bar.update(1)
    bar.close()
    return {k: np.asarray(v) for k, v in poses.items()}


def real_features(folder: str | Path, labels, cfg: RealConfig = RealConfig(),
                  progress: bool = True) -> dict:
    """Features of every labelled pair of ``folder`` (see the module docstring); ``labels`` a
    labels file or its rows."""
    rows = lab.validate(_rows(labels), folder, object_ids)
    if not rows:
        raise UserError(f"{labels} labels no pair")
    by_scene: dict[str, list] = {}
    for r in rows:
        by_scene.setdefault(r.scene, []).append(r)
    out = {k: [] for k in ("pca", "rhf", "y", "scene", "a", "b")}
    poses = {k: [] for k in ("pose_scene", "height", "tilt_deg", "vfov_deg")}
    bar = progress_bar(progress, len(by_scene), f"real features ({Path(folder).name})", unit="scene")
    for name, pairs in by_scene.items():
        cloud = read_cloud(Path(folder) / name)
        seg = hand_segmentation(cloud.label)
        pose, plane, vfov = _pose(cloud)
        fr = sim_aligned_frame(plane)
        poses["pose_scene"].append(name)
        poses["height"].append(pose["height"])
        poses["tilt_deg"].append(pose["tilt_deg"])
        poses["vfov_deg"].append(vfov)
        for r in pairs:
            f = object_pair_features(cloud, seg, r.object_a, r.object_b, fr, cfg)
            if bool(np.any(f["unseen"])) or bool(f["overflow"]):
                raise UserError(f"{name}: pair {r.object_a},{r.object_b} has an unseen object or a capacity "
                                f"overflow (voxels {f['n_points'].tolist()})")
            out["pca"].append(f["pca"])
            out["rhf"].append(f["rhf"])
            out["y"].append(int(r.relation == "on_top"))
            out["scene"].append(name)
            out["a"].append(r.object_a)
            out["b"].append(r.object_b)
        bar.update(1)
    bar.close()
    res = {k: np.asarray(v) for k, v in {**out, **poses}.items()}
    res["pca"] = res["pca"].astype(np.float32)
    res["rhf"] = res["rhf"].astype(np.float32)
    return res


def sensor(data: dict):
    """Mean camera height, tilt and vertical field of view of the real scenes as a ``SimSensor``."""
    vfov = np.asarray(data["vfov_deg"], float)
    return SimSensor(height=round(float(np.mean(data["height"])), 4),
                     tilt_deg=round(float(np.mean(data["tilt_deg"])), 3),
                     vfov_deg=round(float(np.nanmean(vfov)), 3) if np.isfinite(vfov).any() else 43.0)


def cached_real_features(cache: str | Path, folder: str | Path, labels,
                         cfg: RealConfig = RealConfig(), progress: bool = True) -> dict:
    """``real_features`` stored at ``cache`` (``.npz``); recomputed when the labelled rows or the
    config changed (their digest is stored alongside)."""
    key = hashlib.sha256(lab.rows_sha256(_rows(labels)).encode() +
                         json.dumps(rio.jsonable(to_dict(cfg)), sort_keys=True).encode()).hexdigest()
    cache = Path(cache)
    if cache.exists():
        with np.load(cache) as z:
            if str(z["key"]) == key:
                return {k: z[k] for k in z.files if k != "key"}
    data = real_features(folder, labels, cfg, progress)
    cache.parent.mkdir(parents=True, exist_ok=True)
    rio.atomic_save_npz(cache, key=np.asarray(key), **data)
    return data
