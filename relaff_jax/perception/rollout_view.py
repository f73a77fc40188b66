"""Shaded pictures of a rollout's frames: the geoms as they are, by the project's ray caster.

Takes a pair's arm-world ``MjModel`` and recorded geom poses (``frames_xpos`` (F, G, 3),
``frames_xmat`` (F, G, 9), ``sim.animate.rollout_frames``); gives ``frame_camera`` (a
``CameraConfig`` framed on the two objects over all frames, seen obliquely from the robot's
side), ``make_shader`` (one jitted function: geom poses -> an (H, W, 3) uint8 image, every
primitive ray cast exactly by ``raycast.cast_rays``: spheres round, capsules, boxes; coloured by
the geom's ``rgba``, shaded by the surface normal against a light at the camera and dimmed with
depth) and ``shade_frames``. No OpenGL: MuJoCo's renderer needs a GL backend that pip does not
install here.
"""
from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.constants import SEG_BACKGROUND, SEG_NONE

from .camera import camera_rays
from relaff_jax.config.perception import CameraConfig
from .raycast import cast_rays, surface_normals
from .scene import SUPPORTED_GEOMS, SceneGeoms

SKY = (0.93, 0.95, 0.98)
# From the objects towards the camera, in (away from the robot, to the side, up) coordinates:
# from the side and a little beyond the objects, so that the arm reaching in does not hide them.
VIEW_DIR = (0.35, 0.8, 0.6)


def drawn_geoms(model: Any, min_size: float = 0.0015) -> np.ndarray:
    """(G,) bool: geoms worth drawing: a supported primitive, not a collapsed placeholder of an
    unused object part, not transparent. The table plane is drawn."""
    t = np.asarray(model.geom_type)
    size = np.asarray(model.geom_aabb)[:, 3:].max(1)
    return (np.isin(t, list(SUPPORTED_GEOMS)) & ((t == 0) | (size > min_size))
            & (np.asarray(model.geom_rgba)[:, 3] > 0))


def frame_camera(model: Any, frames_xpos: np.ndarray, bodies: tuple[int, ...], width: int = 400,
                 height: int = 300, vfov_deg: float = 40.0, margin: float = 0.12) -> CameraConfig:
    """A camera looking at the objects (geoms of ``bodies``) from ``VIEW_DIR`` (relative to the
    robot-to-objects direction), far enough that
    a sphere around every pose they take in the frames (plus ``margin``) fills the view."""
    geoms = np.flatnonzero(np.isin(np.asarray(model.geom_bodyid), bodies) & drawn_geoms(model))
    radius = np.asarray(model.geom_rbound)[geoms]
    pts = frames_xpos[:, geoms].reshape(-1, 3)
    lo = (pts - np.tile(radius, len(frames_xpos))[:, None]).min(0)
    hi = (pts + np.tile(radius, len(frames_xpos))[:, None]).max(0)
    target = (lo + hi) / 2
    r = float(np.linalg.norm(hi - lo) / 2) + margin
    half = np.deg2rad(min(vfov_deg, vfov_deg * width / height) / 2)
    dist = r / np.sin(half)
    out = target[:2] / max(float(np.linalg.norm(target[:2])), 1e-9) if np.linalg.norm(target[:2]) > 1e-9 else np.array([1.0, 0.0])
    side = np.array([out[1], -out[0]])
    a, b, c = VIEW_DIR
    v = np.array([*(a * out + b * side), c])
    pos = target + dist * v / np.linalg.norm(v)
    return CameraConfig(width=width, height=height, vfov_deg=vfov_deg, position=tuple(map(float, pos)),
                        target=tuple(map(float, target)), near=0.01, far=float(dist + 4 * r + 3.0))


def make_shader(model: Any, cam: CameraConfig) -> Callable[[Any, Any], jax.Array]:
    """``shade(xpos (G, 3), xmat (G, 9)) -> (H, W, 3) uint8``, jitted (one compile per model
    layout and camera). Depth shading: a hit at the camera's target distance keeps its colour,
    one 1 m further back loses 25 %."""
    keep = drawn_geoms(model)
    seg = tuple(int(SEG_BACKGROUND) if k else int(SEG_NONE) for k in keep)
    types = tuple(int(t) for t in np.asarray(model.geom_type))
    size = jnp.asarray(model.geom_size, jnp.float32)
    rgba = np.clip(np.asarray(model.geom_rgba, np.float32), 0, 1)
    rgba[np.asarray(model.geom_type) == 0, :3] = (0.78, 0.74, 0.68)  # the table top
    colour = jnp.asarray(rgba[:, :3])
    origin, dirs = camera_rays(cam)
    origin32, dirs32 = jnp.asarray(origin, jnp.float32), jnp.asarray(dirs, jnp.float32)
    unit = dirs32 / jnp.linalg.norm(dirs32, axis=1, keepdims=True)
    d0 = float(np.linalg.norm(np.subtract(cam.target, cam.position)))

    @jax.jit
    def shade(xpos, xmat):
        scene = SceneGeoms(types, seg, size, jnp.asarray(xpos, jnp.float32),
                           jnp.asarray(xmat, jnp.float32).reshape(-1, 3, 3))
        t, g = cast_rays(scene, origin32, dirs32)
        hit = g >= 0
        pts = origin32 + jnp.where(hit, t, 0.0)[:, None] * dirs32
        n = surface_normals(scene, pts, g)
        lam = jnp.abs(jnp.sum(n * unit, axis=1))  # a headlight: faces turned away are dark
        depth = jnp.linalg.norm(pts - origin32, axis=1)
        dim = jnp.clip(1.0 - 0.25 * (depth - d0), 0.55, 1.1)
        c = colour[jnp.maximum(g, 0)] * ((0.3 + 0.7 * lam) * dim)[:, None]
        c = jnp.where(hit[:, None], c, jnp.asarray(SKY, jnp.float32))
        return jnp.clip(c * 255.0 + 0.5, 0, 255).astype(jnp.uint8).reshape(cam.height, cam.width, 3)

    return shade


def shade_frames(model: Any, frames_xpos: np.ndarray, frames_xmat: np.ndarray, cam: CameraConfig,
                 progress: Callable[[int], None] | None = None) -> list[np.ndarray]:
    """(H, W, 3) uint8 images of every frame; ``progress(f)`` after frame f."""
    shade = make_shader(model, cam)
    out = []
    for f in range(len(frames_xpos)):
        out.append(np.asarray(shade(frames_xpos[f], frames_xmat[f])))
        if progress is not None:
            progress(f)
    return out
