"""Stage 2: depth noise of the simulated Kinect, keyed.

Takes a ``render`` or ``compact_objects`` result, a PRNG key and the config; gives the same
dict with noisy ``depth`` and ``points`` (noise along the optical axis only). Models:
RobWork's polynomial (default), Khoshelham-Elberink, Nguyen (``NOISE_MODELS``).
"""
from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp

from .camera import camera_frame, intrinsics
from relaff_jax.config.perception import NOISE_MODEL_NAMES, CameraConfig, PerceptionConfig


def _sigma_robwork(depth, r):
    d = depth * 1000.0  # mm
    s = 2.344 - 1.202e-2 * r - 1.734e-3 * d + 1.818e-5 * r * r + 6.516e-6 * r * d + 1.233e-6 * d * d
    return jnp.maximum(s, 0.0) / 1000.0


NOISE_MODELS: dict[str, Callable] = {
    "robwork": _sigma_robwork,
    "khoshelham": lambda z, r: 1.425e-3 * z * z,
    "nguyen": lambda z, r: 0.0012 + 0.0019 * (z - 0.4) ** 2,
    "none": lambda z, r: jnp.zeros_like(z),
}
if tuple(NOISE_MODELS) != NOISE_MODEL_NAMES:  # config.py validates against the names
    raise RuntimeError(f"noise models {tuple(NOISE_MODELS)} != config.NOISE_MODEL_NAMES {NOISE_MODEL_NAMES}")


def pixel_radius(pixel, cam: CameraConfig):
    """Distance (px) of flat pixel indices from the image centre, rescaled to a 640-wide image
    so the RobWork polynomial (fitted at 640x480) means the same at any resolution."""
    _, _, cx, cy = intrinsics(cam)
    u = (pixel % cam.width).astype(jnp.float32) + 0.5 - cx
    v = (pixel // cam.width).astype(jnp.float32) + 0.5 - cy
    return jnp.hypot(u, v) * (640.0 / cam.width)


def depth_noise_sigma(depth, pixel, cam: CameraConfig, model: str):
    """Noise std (m) for ``depth`` (...,) metres at flat pixel indices ``pixel`` (...,)."""
    if model not in NOISE_MODELS:
        raise ValueError(f"unknown noise model {model!r}; valid: {sorted(NOISE_MODELS)}")
    return NOISE_MODELS[model](depth, pixel_radius(pixel, cam))


def add_depth_noise(cloud: dict, key, cfg: PerceptionConfig) -> dict:
    """Add z ~ N(0, sigma(depth, r)) along the optical axis to every valid pixel of ``cloud``.

    ``cloud`` is a ``render`` result (every pixel) or a ``compact_objects`` result (object pixels
    only: the table is dropped anyway, so this draws 32k instead of 307k normals). Valid entries
    have pixel >= 0 and seg >= 0. Only the camera-frame z of a point changes (its camera x, y
    stay): the paper's "noise on the z-coordinate". Returns a copy with new depth and points.
    """
    cam = cfg.camera
    depth = cloud["depth"].reshape(-1)
    pixel = cloud.get("pixel")
    if pixel is None:
        pixel = jnp.arange(depth.shape[0], dtype=jnp.int32)
    valid = (pixel >= 0) & (cloud["seg"] >= 0)
    sigma = depth_noise_sigma(depth, pixel, cam, cfg.noise.model)
    eps = jnp.where(valid, sigma * jax.random.normal(key, sigma.shape), 0.0)
    fwd = jnp.asarray(camera_frame(cam)[1][:, 2], jnp.float32)
    out = dict(cloud)
    out["depth"] = (depth + eps).reshape(cloud["depth"].shape)
    out["points"] = cloud["points"] + eps[:, None] * fwd
    return out
