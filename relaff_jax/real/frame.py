"""The table frame of a real scene and the camera's pose over the table.

Takes a table plane (4,) in the camera frame (unit normal n towards the camera, n . p + d = 0,
as ``segment.fit_table_plane`` gives it); gives

* ``table_frame(plane, flip=False)`` -> dict(rotation (3, 3), origin (3,)): z = n (up, the
  camera side); origin = the point where the camera's optical axis (camera z) meets the plane;
  x = the optical axis projected on the plane (the horizontal viewing direction, away from the
  camera), y = z x x. ``flip`` turns x and y by 180 degrees about z (x towards the camera, as
  in the simulation's robot frame, where the camera at +x looks towards -x). The origin depends
  only on where the camera points, not on what the scene holds, so two scenes taken from the
  same pose share a frame.
* ``to_table(points (..., 3), frame)``, ``vectors_to_table(v (..., 3), frame)``.
* ``camera_pose(plane)`` -> dict(height (m, camera above the plane), tilt_deg (angle between the
  optical axis and the downward plane normal: 0 = looking straight down), position (3,) and
  target (3,) = origin in the table frame).
* ``camera_pose_stats(planes)`` -> mean and standard deviation of height and tilt over scenes.
* ``sim_camera(height, tilt_deg, target, base)`` -> a simulation ``CameraConfig`` at that
  height and tilt, on the +x side of ``target`` looking towards -x (the simulation's layout).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.config.perception import CameraConfig

_MIN_COS = 1e-3  # optical axis within 0.06 degrees of parallel to the table: no hit point


def _check(plane) -> np.ndarray:
    plane = np.asarray(plane, np.float64).ravel()
    if plane.shape != (4,) or not np.all(np.isfinite(plane)) or abs(np.linalg.norm(plane[:3]) - 1) > 1e-4:
        raise UserError(f"a table plane must be 4 finite numbers with a unit normal, got {plane}")
    if plane[3] < 0:  # normal towards the camera (the origin)
        plane = -plane
    if plane[2] > -_MIN_COS:
        raise UserError("the camera's optical axis does not meet the table plane (it looks away from or "
                        f"along the table: normal {plane[:3].round(3)})")
    return plane


def table_frame(plane, flip: bool = False) -> dict:
    """Table frame of a camera-frame plane (see the module docstring): rotation (3, 3) whose rows
    are the table's x, y, z axes in camera coordinates, origin (3,) camera-frame metres."""
    plane = _check(plane)
    n, d = plane[:3], plane[3]
    view = np.array([0.0, 0.0, 1.0])
    origin = view * (-d / n[2])
    x = view - (view @ n) * n
    if np.linalg.norm(x) < 1e-9:  # looking straight down: camera "up" (-y) projected instead
        x = np.array([0.0, -1.0, 0.0]) - (-n[1]) * n
    x /= np.linalg.norm(x)
    if flip:
        x = -x
    y = np.cross(n, x)
    return dict(rotation=np.stack([x, y, n]), origin=origin)


def to_table(points, frame: dict) -> np.ndarray:
    """Camera-frame points (..., 3) -> table frame (NaN stays NaN)."""
    return (np.asarray(points, np.float64) - frame["origin"]) @ frame["rotation"].T


def vectors_to_table(vectors, frame: dict) -> np.ndarray:
    """Camera-frame directions (..., 3) (e.g. normals) -> table frame (rotation only)."""
    return np.asarray(vectors, np.float64) @ frame["rotation"].T


def camera_pose(plane) -> dict:
    """Camera height (m) over the plane, tilt (degrees), position and target in the table frame."""
    plane = _check(plane)
    frame = table_frame(plane)
    tilt = float(np.degrees(np.arccos(np.clip(-plane[2], -1.0, 1.0))))
    return dict(height=float(plane[3]), tilt_deg=tilt, position=to_table(np.zeros(3), frame),
                target=np.zeros(3))


def camera_pose_stats(planes) -> dict:
    """Mean and spread of the camera pose over scenes: dict(n, height_mean, height_std,
    height_min, height_max, tilt_mean_deg, tilt_std_deg, tilt_min_deg, tilt_max_deg)
    (standard deviations with ddof=0)."""
    poses = [camera_pose(p) for p in planes]
    if not poses:
        raise UserError("camera_pose_stats needs at least one plane")
    h = np.array([p["height"] for p in poses])
    t = np.array([p["tilt_deg"] for p in poses])
    return dict(n=len(poses), height_mean=float(h.mean()), height_std=float(h.std()),
                height_min=float(h.min()), height_max=float(h.max()), tilt_mean_deg=float(t.mean()),
                tilt_std_deg=float(t.std()), tilt_min_deg=float(t.min()), tilt_max_deg=float(t.max()))


def sim_camera(height: float, tilt_deg: float, target=(0.7, 0.0, 0.0), base: CameraConfig = CameraConfig()):
    """A simulation ``CameraConfig`` (``base`` with a new pose) ``height`` m above the table top
    (z = 0 in simulation) and tilted by ``tilt_deg`` from straight down, looking at ``target``
    from its +x side, as the simulation's default camera does."""
    if height <= 0 or not 0 <= tilt_deg < 90:
        raise UserError(f"need height > 0 and 0 <= tilt < 90 degrees, got {height}, {tilt_deg}")
    tx, ty, tz = (float(v) for v in target)
    pos = (tx + (height - tz) * float(np.tan(np.radians(tilt_deg))), ty, height)
    return dataclasses.replace(base, position=pos, target=(tx, ty, tz))
