"""The pinhole depth camera's static geometry (numpy, evaluated once per trace).

Takes a ``CameraConfig``; gives the camera pose (``camera_frame``), intrinsics, one ray per
pixel (``camera_rays``: origin (3,), directions (H*W, 3)) and the same rays grouped by
image tile (``tile_rays``: (n_tiles, tile*tile, 3)).
"""
from __future__ import annotations

import numpy as np

from relaff_jax.config.perception import CameraConfig


def camera_frame(cam: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Camera origin (3,) and rotation (3, 3) whose columns are the camera x (image right),
    y (image down) and z (optical axis) axes in the robot frame (OpenCV convention)."""
    pos = np.asarray(cam.position, np.float64)
    fwd = np.asarray(cam.target, np.float64) - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("camera looks straight up or down; cannot orient the image with world +z up")
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return pos, np.stack([right, down, fwd], axis=1)


def intrinsics(cam: CameraConfig) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in pixels; 640x480 at 43 deg gives fx = fy ~ 609.3, (320, 240)."""
    fy = (cam.height / 2.0) / np.tan(np.deg2rad(cam.vfov_deg) / 2.0)
    return fy, fy, cam.width / 2.0, cam.height / 2.0


def camera_rays(cam: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Static rays: origin (3,) and directions (H*W, 3) in the robot frame, row-major pixels.

    Pixel (v, u) looks through ((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy, 1) in the camera frame;
    directions are *not* normalised, their camera-z component is 1, so the ray parameter of a
    hit is the depth z.
    """
    fx, fy, cx, cy = intrinsics(cam)
    pos, rot = camera_frame(cam)
    u = (np.arange(cam.width) + 0.5 - cx) / fx
    v = (np.arange(cam.height) + 0.5 - cy) / fy
    uu, vv = np.meshgrid(u, v)
    d_cam = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    return pos, d_cam @ rot.T


# Ray-primitive tests work on structure-of-arrays: lo (3,) local origin, ld (3, N) local
# directions, so every operation is a plain (N,) vector op (XLA CPU vectorises these; reductions


def tile_rays(cam: CameraConfig, tile: int) -> tuple[np.ndarray, np.ndarray]:
    """Static per-tile rays: dirs (n_tiles, tile*tile, 3) and flat pixel index (n_tiles, tile*tile).

    Tiles are numbered row-major over the (H / tile, W / tile) grid."""
    _, dirs = camera_rays(cam)
    H, W = cam.height, cam.width
    pix = np.arange(H * W, dtype=np.int32).reshape(H // tile, tile, W // tile, tile)
    pix = pix.transpose(0, 2, 1, 3).reshape(-1, tile * tile)
    return dirs[pix], pix
